"""The stall rule: an episode in which a car stands still too long ends, and is not a success."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest

import sofar_env  # noqa: F401  (registers the environments)
from sofar_env.config import ConfigError, make_env_config
from sofar_env.multi_agent import parallel_env


def _run(env_id: str, seed: int, options: dict, **kwargs):
    env = gym.make(env_id, **kwargs)
    env.reset(seed=seed, options=options)
    steps, info, terminated, truncated = 0, {}, False, False
    while not (terminated or truncated):
        _, _, terminated, truncated, info = env.step(np.array([0.5], np.float32))
        steps += 1
    return steps, info, terminated, truncated


def test_stuck_behind_a_car_with_no_room_beside_it_stalls():
    """Kentucky, rho = 0, seed 0: a car parked 1 m left of the raceline where the track is 6.1 m wide
    leaves 2.3 m and 2.1 m beside it, less than the 2.95 m the barrier (b = 2.7 m) and the track margin
    need; the ego stops behind it at about 17.6 s and the rule ends the episode 20 s later."""
    steps, info, terminated, truncated = _run("SOfAR-Kentucky-v0", 0, {"rho": 0.0}, config={"race": {"duration": 60.0}})
    assert terminated and not truncated
    assert info["stalled"] and info["is_success"] is False
    assert not info["collision"] and not info["off_track"]
    assert 20.0 <= info["sim_time"] < 45.0


def test_with_the_rule_off_the_same_episode_runs_to_the_end():
    steps, info, terminated, truncated = _run("SOfAR-Kentucky-v0", 0, {"rho": 0.0}, stall_seconds=None,
                                              config={"race": {"duration": 60.0}})
    assert truncated and not terminated and not info["stalled"]
    assert math.isclose(info["sim_time"], 60.0, abs_tol=1e-6)


@pytest.mark.parametrize("seconds,steps", [(0.5, 5), (1.0, 10)])
def test_the_rule_counts_consecutive_slow_steps(seconds, steps):
    """With ``stall_speed`` above any speed every step is slow: the episode ends after exactly
    ``stall_seconds / dt`` control steps."""
    n, info, terminated, _ = _run("SOfAR-Monza-v0", 3, {}, stall_speed=500.0, stall_seconds=seconds)
    assert terminated and info["stalled"] and n == steps


def test_the_rule_applies_per_car_in_the_parallel_env():
    env = parallel_env("Monza", n_agents=2, stall_speed=500.0, stall_seconds=0.3)
    env.reset(seed=0)
    for _ in range(3):
        _, _, terms, truncs, infos = env.step({a: np.array([0.5], np.float32) for a in env.agents})
    assert all(terms.values()) and not any(truncs.values())
    assert all(i["stalled"] and i["is_success"] is False for i in infos.values())
    assert env.agents == []


@pytest.mark.parametrize("key,value,words", [
    ("stall_speed", -1.0, "stall_speed must be a finite number >= 0"),
    ("stall_speed", float("nan"), "stall_speed must be a finite number >= 0"),
    ("stall_seconds", float("inf"), "stall_seconds must be None (off) or a finite number >= 0"),
    ("stall_seconds", -5.0, "stall_seconds must be None (off) or a finite number >= 0"),
    ("stall_seconds", "20", "stall_seconds must be None (off) or a finite number >= 0"),
])
def test_bad_stall_settings_are_refused(key, value, words):
    with pytest.raises(ConfigError) as err:
        make_env_config({key: value})
    assert words in str(err.value)


@pytest.mark.parametrize("seconds,steps", [(None, None), (0, None), (20.0, 200), (0.25, 3)])
def test_stall_steps(seconds, steps):
    assert make_env_config(stall_seconds=seconds).stall_steps == steps
