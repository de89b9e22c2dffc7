"""PASTA reaches the balanced point of a non-convex front; linear scalarisation does not.

The one-step bandit of ``synthetic_envs.NonConvexBandit`` pays ``(f1, f2) = (a, (1 - a)^3)``
for an action a in [0, 1]. The front is concave-in: every positive weighted sum
``c1 a + c2 (1 - a)^3`` is convex in a, so linear scalarisation (equal weights here)
drives the policy to an extreme (a -> 1: f2 = 0), while the balanced point
``f1 = f2 ~ 0.32`` (a ~ 0.32) lies in the dent. Both agents use the same code, seed and
budget; only ``scalarization`` differs. PASTA runs its mu schedule down to a small
temperature (decay only: with two objectives on a pure trade-off the gradient conflict
ratio is always 1, and the conflict boost would hold mu at mu_max).
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
import torch

from sofar_agents import PASTA, PASTAConfig
from sofar_agents.wrappers import LinearReward
from synthetic_envs import NonConvexBandit, bandit_rewards

TOTAL = 8192


def _train(scalarization: str, seed: int = 0) -> tuple[float, PASTA]:
    torch.set_num_threads(1)
    venv = gym.vector.SyncVectorEnv([lambda: LinearReward(NonConvexBandit()) for _ in range(8)],
                                    autoreset_mode=gym.vector.AutoresetMode.SAME_STEP)
    config = PASTAConfig(
        learning_rate=1e-3, n_steps=32, batch_size=64, n_epochs=4, hidden_sizes=(32, 32), critic_head_hidden=0,
        scalarization=scalarization, preference_sampling="fixed",
        mu_max=1.0, mu_ema=0.2, mu_decay_steps=TOTAL // 2, conflict_boost=False,
    )
    agent = PASTA(2, 2, [0.0], [1.0], config, preference=[0.5, 0.5], seed=seed, objective_names=["f1", "f2"])
    agent.learn(venv, TOTAL)
    venv.close()
    return float(agent.predict(np.zeros(2))[0]), agent


@pytest.fixture(scope="module")
def results() -> dict[str, tuple[float, PASTA]]:
    return {"stch": _train("stch"), "linear": _train("linear")}


def test_front_is_non_convex() -> None:
    a = np.linspace(0, 1, 201)
    f = bandit_rewards(a)
    linear = f.sum(axis=1)
    assert linear.argmax() in (0, 200)  # equal weights pick an extreme
    balanced = a[np.argmax(f.min(axis=1))]
    assert 0.3 < balanced < 0.34
    assert linear[np.argmax(f.min(axis=1))] < linear.max() - 0.3  # the balanced point lies in the dent


def test_linear_scalarisation_goes_to_an_extreme(results: dict[str, tuple[float, PASTA]]) -> None:
    a, _ = results["linear"]
    f1, f2 = bandit_rewards(a)
    assert min(f1, f2) < 0.02, (a, f1, f2)


def test_pasta_reaches_the_balanced_trade_off(results: dict[str, tuple[float, PASTA]]) -> None:
    a, agent = results["stch"]
    f1, f2 = bandit_rewards(a)
    assert 0.2 < a < 0.5, (a, f1, f2)
    assert min(f1, f2) > 0.15, (a, f1, f2)
    assert agent.mu_controller.mu < 0.1  # the schedule reached the Tchebycheff regime
    a_lin, _ = results["linear"]
    assert min(f1, f2) > min(bandit_rewards(a_lin)) + 0.1
