"""GAE against hand computations, and the bootstrap targets produced by a rollout."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import pytest
import torch

from sofar_agents import PASTA, PASTAConfig, compute_gae
from sofar_agents.wrappers import LinearReward

# One env, five transitions: terminated at t = 1, truncated (time limit) at t = 3.
REWARDS = np.array([1.0, 2.0, 3.0, 4.0, 5.0])
VALUES = np.array([0.5, 0.6, 0.7, 0.8, 0.9])
# V of the true successor of each transition: V(s_1), ignored (terminal), V(s_3),
# V(final_obs) of the truncated episode, V(last_obs) after the rollout.
NEXT_VALUES = np.array([0.6, 99.0, 0.8, 10.0, 2.0])
TERMINATED = np.array([False, True, False, False, False])
TRUNCATED = np.array([False, False, False, True, False])
DISCOUNT, LAMBDA = 0.9, 0.8


def test_gae_matches_hand_computation() -> None:
    adv, ret = compute_gae(REWARDS, VALUES, NEXT_VALUES, TERMINATED, TRUNCATED, DISCOUNT, LAMBDA)
    a4 = 5.0 + 0.9 * 2.0 - 0.9  # bootstrap from the last observation
    a3 = 4.0 + 0.9 * 10.0 - 0.8  # truncated: bootstrap from V(final_obs), no flow from t = 4
    a2 = (3.0 + 0.9 * 0.8 - 0.7) + 0.9 * 0.8 * a3
    a1 = 2.0 - 0.6  # terminated: no bootstrap
    a0 = (1.0 + 0.9 * 0.6 - 0.5) + 0.9 * 0.8 * a1
    expected = np.array([a0, a1, a2, a3, a4])
    np.testing.assert_allclose(adv, expected, rtol=1e-12)
    np.testing.assert_allclose(ret, expected + VALUES, rtol=1e-12)
    assert expected[3] == pytest.approx(12.2) and expected[2] == pytest.approx(11.804)


def test_gae_lambda_limits() -> None:
    # lambda = 0: one-step TD errors.
    adv0, _ = compute_gae(REWARDS, VALUES, NEXT_VALUES, TERMINATED, TRUNCATED, DISCOUNT, 0.0)
    td = REWARDS + DISCOUNT * (1 - TERMINATED) * NEXT_VALUES - VALUES
    np.testing.assert_allclose(adv0, td)
    # lambda = 1: discounted returns to the episode end (+ bootstrap on truncation) minus V.
    _, ret1 = compute_gae(REWARDS, VALUES, NEXT_VALUES, TERMINATED, TRUNCATED, DISCOUNT, 1.0)
    mc = np.array([1 + 0.9 * 2, 2, 3 + 0.9 * (4 + 0.9 * 10), 4 + 0.9 * 10, 5 + 0.9 * 2])
    np.testing.assert_allclose(ret1, mc)


def test_gae_broadcasts_over_envs_and_objectives() -> None:
    k = 3
    scale = np.array([1.0, -2.0, 0.5])
    rewards = REWARDS[:, None, None] * scale  # (T, 1 env, K)
    values = VALUES[:, None, None] * scale
    next_values = NEXT_VALUES[:, None, None] * scale
    adv, _ = compute_gae(rewards, values, next_values, TERMINATED[:, None], TRUNCATED[:, None], DISCOUNT, LAMBDA)
    ref, _ = compute_gae(REWARDS, VALUES, NEXT_VALUES, TERMINATED, TRUNCATED, DISCOUNT, LAMBDA)
    assert adv.shape == (5, 1, k)
    np.testing.assert_allclose(adv[:, 0, :], ref[:, None] * scale)
    with pytest.raises(ValueError):
        compute_gae(rewards, values[:-1], next_values, TERMINATED, TRUNCATED)


class _EpisodeEnv(gym.Env):
    """Deterministic episodes: even ones terminate after 2 steps, odd ones are truncated after 3."""

    def __init__(self) -> None:
        self.observation_space = gym.spaces.Box(-10, 10, shape=(2,), dtype=np.float32)
        self.action_space = gym.spaces.Box(np.array([0.05], np.float32), np.array([1.0], np.float32))
        self.reward_space = gym.spaces.Box(-1, 1, shape=(2,), dtype=np.float32)
        self._episode = -1

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        self._episode += 1
        self._t = 0
        return np.array([self._episode, 0.0], np.float32), {}

    def step(self, action: Any):
        self._t += 1
        obs = np.array([self._episode, self._t], np.float32)
        terminated = self._episode % 2 == 0 and self._t == 2
        truncated = self._episode % 2 == 1 and self._t == 3
        return obs, np.array([1.0, -0.5], np.float32), terminated, truncated, {}


def test_rollout_bootstrap_targets() -> None:
    torch.set_num_threads(1)
    venv = gym.vector.SyncVectorEnv([lambda: LinearReward(_EpisodeEnv())],
                                    autoreset_mode=gym.vector.AutoresetMode.SAME_STEP)
    agent = PASTA(2, 2, [0.05], [1.0], PASTAConfig(hidden_sizes=(16,), critic_head_hidden=0,
                                                   preference_sampling="fixed"), seed=3)
    buf = agent.collect(venv, 9)  # episodes: term at t=1, trunc at t=4, term at t=6, last partial
    term, trunc = buf.terminated[:, 0], buf.truncated[:, 0]
    np.testing.assert_array_equal(np.flatnonzero(term), [1, 6])
    np.testing.assert_array_equal(np.flatnonzero(trunc), [4])
    np.testing.assert_allclose(buf.rewards[:, 0], np.tile([1.0, -0.5], (9, 1)))

    def value(obs: list[float]) -> np.ndarray:
        x = torch.as_tensor([[*obs, *agent.preference]], dtype=torch.float32)
        with torch.no_grad():
            return agent.critic(x).numpy()[0]

    nv = buf.next_values[:, 0]
    np.testing.assert_allclose(nv[1], 0.0)  # terminated
    np.testing.assert_allclose(nv[6], 0.0)
    np.testing.assert_allclose(nv[4], value([1.0, 3.0]), rtol=1e-5)  # V(final_obs) of episode 1
    for t in (0, 2, 3, 5, 7):  # inside an episode: the next stored value
        np.testing.assert_allclose(nv[t], buf.values[t + 1, 0])
    np.testing.assert_allclose(nv[8], value([3.0, 2.0]), rtol=1e-5)  # V(last_obs)
    venv.close()
