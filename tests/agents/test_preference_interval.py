"""Preferences drawn every ``preference_interval`` steps: segments, their cut and their bootstrap."""

from __future__ import annotations

import dataclasses

import gymnasium as gym
import numpy as np
import pytest

torch = pytest.importorskip("torch")

from sofar_agents.evaluation.preference_probe import TradeoffEnv  # noqa: E402
from sofar_agents.pasta import PASTA, PASTAConfig  # noqa: E402
from sofar_agents.pasta.networks import network_inputs  # noqa: E402


def _agent(interval: int) -> PASTA:
    cfg = dataclasses.replace(PASTAConfig(), n_steps=64, batch_size=32, n_epochs=1, hidden_sizes=(16,),
                              critic_head_hidden=0, preference_interval=interval)
    return PASTA(4, 5, [0.05], [1.0], cfg, preference=(0.5, 0.3, 0.05, 0.05, 0.1), seed=3)


def _vec(horizon: int = 1000) -> gym.vector.SyncVectorEnv:
    # crash-free, so that every episode runs its horizon and only the preference switches cut it
    return gym.vector.SyncVectorEnv([lambda: TradeoffEnv(horizon=horizon, crash_base=0.0, crash_slope=0.0)] * 2,
                                    autoreset_mode=gym.vector.AutoresetMode.SAME_STEP)


def test_preferences_change_every_interval_and_the_segment_is_cut():
    agent = _agent(10)
    buf = agent.collect(_vec(), 64)
    prefs = buf.preferences  # (T, n, K)
    for t in range(63):
        switch = (t + 1) % 10 == 0
        assert bool(np.all(buf.truncated[t])) == switch
        same = np.all(prefs[t] == prefs[t + 1], axis=-1)
        assert bool(np.any(same)) != switch and bool(np.all(same)) != switch


def test_the_cut_bootstraps_from_the_value_under_the_old_preference():
    agent = _agent(10)
    buf = agent.collect(_vec(), 32)
    t = 9  # the first switch
    x = network_inputs(buf.obs[t + 1], buf.preferences[t])  # the next state, the preference driven so far
    with torch.no_grad():
        expected = agent.critic(x).numpy()
    np.testing.assert_allclose(buf.next_values[t], expected, rtol=1e-6)
    assert not np.allclose(buf.next_values[t], buf.values[t + 1])  # not the value under the new preference


def test_interval_zero_keeps_one_preference_per_episode():
    agent = _agent(0)
    buf = agent.collect(_vec(), 64)
    assert not buf.truncated.any()
    assert np.all(buf.preferences == buf.preferences[0])


@pytest.mark.parametrize("value", [-1, 2.5, True, "10"])
def test_bad_intervals_are_refused(value):
    with pytest.raises(ValueError, match="preference_interval"):
        PASTAConfig(preference_interval=value)
