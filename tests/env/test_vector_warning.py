"""Gymnasium's passive checker through plain ``gymnasium.make``: off in vector mode, on in scalar mode."""

from __future__ import annotations

import pickle
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.wrappers import PassiveEnvChecker

import sofar_env  # noqa: F401  (registers the ids)
from sofar_env.config import make_env_config
from sofar_env.registration import CUSTOM_ID, ENV_IDS, INTERACTIVE_IDS

SHORT = {"duration": 0.5}


def _wrappers(env) -> list[type]:
    """The wrapper classes around the env, outermost first (a subclass of a Gymnasium wrapper as that wrapper)."""
    known = (gym.wrappers.TimeLimit, gym.wrappers.OrderEnforcing, PassiveEnvChecker)
    chain = []
    while isinstance(env, gym.Wrapper):
        chain.append(next((k for k in known if isinstance(env, k)), type(env)))
        env = env.env
    return chain


def _run_recording_warnings(env) -> list[str]:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        env.reset(seed=0)
        for _ in range(3):
            _, reward, _, _, _ = env.step(np.array([0.5], np.float32))
    env.close()
    return [str(w.message) for w in caught]


@pytest.mark.parametrize("how", ["kwarg", "config", "EnvConfig"])
def test_vector_mode_with_plain_make_has_no_checker_warning(how):
    kwargs = {"kwarg": {"reward_mode": "vector", "race": SHORT},
              "config": {"config": {"reward_mode": "vector", "race": SHORT}},
              "EnvConfig": {"config": make_env_config(reward_mode="vector", race=SHORT)}}[how]
    env = gym.make("SOfAR-Monza-v0", **kwargs)
    assert PassiveEnvChecker not in _wrappers(env)
    messages = _run_recording_warnings(env)
    assert not [m for m in messages if "must be a float" in m or "reward" in m.lower()], messages


def test_vector_mode_still_returns_the_declared_vector():
    env = gym.make("SOfAR-Indianapolis-Interactive-v0", reward_mode="vector", race=SHORT)
    env.reset(seed=1)
    _, reward, _, _, _ = env.step(np.array([0.5], np.float32))
    assert isinstance(reward, np.ndarray) and reward.shape == (5,) and reward.dtype == np.float32
    assert env.unwrapped.reward_space.contains(reward)
    env.close()


@pytest.mark.parametrize("env_id", [ENV_IDS[0], INTERACTIVE_IDS[1]])
def test_scalar_mode_is_passive_checked_where_make_puts_the_checker(env_id):
    env = gym.make(env_id, race=SHORT)
    assert _wrappers(env) == [gym.wrappers.OrderEnforcing, PassiveEnvChecker]  # no TimeLimit: the env ends itself
    checker = env.env
    assert not checker.checked_reset and not checker.checked_step
    messages = _run_recording_warnings(env)
    assert checker.checked_reset and checker.checked_step  # the checker ran on the first reset and step
    assert messages == []  # and found nothing to report in a correct scalar env


def test_checker_flags_a_real_problem_in_scalar_mode():
    """The checker really is active in scalar mode: an observation of the wrong dtype for its space is reported."""
    env = gym.make(ENV_IDS[0], race=SHORT)
    base = env.unwrapped
    base.observation_space = gym.spaces.Box(-1.0, 1.0, (12,), np.float64)  # the float32 observation mismatches it
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        env.reset(seed=0)
    assert any("obs returned by the `reset()`" in str(w.message) for w in caught), [str(w.message) for w in caught]
    env.close()


def test_every_registered_spec_leaves_make_checker_off_and_pickles():
    for env_id in (*ENV_IDS, *INTERACTIVE_IDS, CUSTOM_ID):
        spec = gym.spec(env_id)
        assert spec.disable_env_checker is True and isinstance(spec.entry_point, str)
        assert pickle.loads(pickle.dumps(spec)) == spec


def test_spec_round_trip_keeps_one_checker_in_scalar_mode_and_none_in_vector_mode():
    for mode, expected in (("scalar", 1), ("vector", 0)):
        env = gym.make(ENV_IDS[1], reward_mode=mode, race=SHORT)
        again = gym.make(env.spec)
        assert _wrappers(again).count(PassiveEnvChecker) == expected
        env.close()
        again.close()
