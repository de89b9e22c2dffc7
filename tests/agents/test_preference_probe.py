"""The trade-off environment and the preference response: analytic checks and a short training run."""

from __future__ import annotations

import dataclasses

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from sofar_agents.evaluation.preference_probe import (
    TradeoffEnv,
    preference_response,
    probe_observations,
    safety_preferences,
)


def test_env_passes_gymnasium_checker():
    check_env(TradeoffEnv(), skip_render_check=True)


def test_expected_returns_trade_safety_against_overtakes():
    env = TradeoffEnv()
    low, high = env.expected_returns(0.05, 0.8), env.expected_returns(1.0, 0.8)
    assert high[0] < low[0] < 0.0  # a bold gamma crashes more
    assert high[1] > low[1] > 0.0  # and overtakes more
    # d = 0: no crash, no overtake, the horizon's worth of progress
    none = env.expected_returns(0.5, 0.0)
    assert none[0] == 0.0 and none[1] == 0.0 and none[2] == pytest.approx(100 * 0.85)


def test_empirical_crash_rate_matches_the_closed_form():
    env = TradeoffEnv(horizon=50, crash_base=0.004, crash_slope=0.01)
    crashes = 0
    n = 2000
    for ep in range(n):
        env.reset(seed=ep)
        env._d = 1.0  # fixed density for the check
        while True:
            _, _, term, trunc, info = env.step(np.array([0.6], np.float32))
            if term:
                crashes += 1
            if term or trunc:
                break
    expected = -env.expected_returns(0.6, 1.0)[0]
    assert crashes / n == pytest.approx(expected, abs=4 * np.sqrt(expected * (1 - expected) / n))


@pytest.mark.parametrize("weights", [[-0.1], [0.95], [0.5, 1.2]])
def test_safety_preferences_reject_weights_outside_the_family(weights):
    with pytest.raises(ValueError, match="safety weight"):
        safety_preferences(weights)


def test_safety_preferences_sum_to_one():
    p = safety_preferences([0.1, 0.9])
    assert np.allclose(p.sum(axis=1), 1.0) and p[0, 1] == pytest.approx(0.8) and p[1, 1] == pytest.approx(0.0)


class _Linear:
    """A stand-in policy whose gamma falls linearly with the safety weight (checks the reader)."""

    def predict(self, obs, deterministic=True, preference=None):
        return np.full((len(obs), 1), 1.0 - preference[0])


def test_response_reads_mean_spread_and_direction():
    r = preference_response(_Linear(), probe_observations(), safety_preferences([0.1, 0.5, 0.9]))
    assert np.allclose(r.mean, [0.9, 0.5, 0.1]) and r.spread == pytest.approx(0.8)
    assert r.monotone(decreasing=True) and not r.monotone(decreasing=False)


def test_short_training_moves_gamma_with_the_preference():
    """A freshly initialised PASTA is indifferent to its preference; after 12,000 steps of training with a
    sharp attention the safety-first preference chooses a lower gamma than the pace-first one."""
    torch = pytest.importorskip("torch")
    from sofar_agents.pasta import PASTA, PASTAConfig

    torch.set_num_threads(1)
    cfg = dataclasses.replace(PASTAConfig(), action_squashing="clip", initial_action=0.5, log_std_init=-1.2,
                              n_steps=512, batch_size=256, n_epochs=5, fixed_mu=0.1, hidden_sizes=(64, 64),
                              conflict_every=8)
    vec_env = gym.vector.SyncVectorEnv([TradeoffEnv] * 2, autoreset_mode=gym.vector.AutoresetMode.SAME_STEP)
    agent = PASTA(4, 5, [0.05], [1.0], cfg, preference=(0.5, 0.3, 0.05, 0.05, 0.1), seed=1)
    prefs = safety_preferences([0.1, 0.5, 0.9])
    before = preference_response(agent, probe_observations(), prefs)
    assert before.spread < 0.01
    agent.learn(vec_env, 12_000, log_interval=0)
    after = preference_response(agent, probe_observations(), prefs)
    assert after.monotone(decreasing=True)
    assert after.mean[0] - after.mean[-1] > 0.05
