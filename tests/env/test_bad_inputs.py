"""Bad input to the environments: a clear error naming what is wrong, and nothing changed by the failed call."""

import math

import gymnasium as gym
import numpy as np
import pytest

import sofar_env  # noqa: F401
from sofar_env.config import ConfigError

SHORT = {"race": {"duration": 5.0}}


@pytest.mark.parametrize("kwargs, error, words", [
    ({"config": {"race": {"dt": math.nan}}}, ValueError, ["race.dt", "finite"]),
    ({"config": {"race": {"duration": math.nan}}}, ValueError, ["race.duration", "finite"]),
    ({"config": {"race": {"duration": 0.01}}}, ValueError, ["race.duration", "at least one step"]),
    ({"config": {"race": {"start_speed_fraction": (0.9, 0.5)}}}, ValueError, ["start_speed_fraction"]),
    ({"offsets": (20.0,)}, ValueError, ["offsets", "n = 20"]),
    ({"n_opponents": 30, "track": "Kentucky"}, ValueError, ["n_opponents = 30", "at most"]),
    ({"stack": "papr"}, ConfigError, ["valid presets"]),
    ({"scenario": "mars"}, ConfigError, ["valid scenarios"]),
    ({"rho": 5.0}, ValueError, ["rho"]),
    ({"colour": "red"}, ConfigError, ["unknown configuration key", "colour"]),
])
def test_bad_configuration(kwargs, error, words):
    with pytest.raises(error) as info:
        env = gym.make("SOfAR-LagunaSeca-v0", **kwargs)
        env.reset(seed=0)  # some checks need the circuit, which is loaded at the first reset
    for w in words:
        assert w in str(info.value), (w, str(info.value))


@pytest.mark.parametrize("options, words", [
    ({"rho": 5.0}, ["rho", "[0, 2]"]),
    ({"rho": "fast"}, ["rho"]),
    ({"n_opponents": 2.5}, ["n_opponents", "whole number"]),
    ({"n_opponents": -1}, ["n_opponents"]),
    ({"n_opponents": 400}, ["n_opponents = 400", "at most"]),
    ({"start_speed": 200.0}, ["start_speed", "m/s"]),
    ({"start_speed": -1.0}, ["start_speed"]),
    ({"start_s": math.nan}, ["start_s", "finite"]),
    ({"colour": 1}, ["unknown reset option", "colour"]),
])
def test_failed_reset_changes_nothing(options, words):
    env = gym.make("SOfAR-LagunaSeca-v0", config=SHORT).unwrapped
    env.reset(seed=0)
    env.step(np.array([0.5], np.float32))
    before = (env.race.states.copy(), env.race.time, env.race.opponents.s.copy(), env.race.opponents.rho,
              env.np_random.bit_generator.state)
    with pytest.raises(ValueError) as info:
        env.reset(seed=1, options=options)
    for w in words:
        assert w in str(info.value), (w, str(info.value))
    after = (env.race.states, env.race.time, env.race.opponents.s, env.race.opponents.rho,
             env.np_random.bit_generator.state)
    np.testing.assert_array_equal(before[0], after[0])
    assert before[1] == after[1] and before[3] == after[3] and before[4] == after[4]
    np.testing.assert_array_equal(before[2], after[2])
    # the episode goes on where it was
    _, _, _, _, info = env.step(np.array([0.5], np.float32))
    assert info["sim_time"] == pytest.approx(0.2)


@pytest.mark.parametrize("action, words", [
    ("0.5", ["one real number", "str"]),
    ("abc", ["one real number", "str"]),
    (None, ["one real number", "NoneType"]),
    (True, ["one real number", "bool"]),
    ([0.1, 0.2], ["exactly one value"]),
    (np.array([np.nan], np.float32), ["non-finite"]),
    (np.array([np.inf]), ["non-finite"]),
])
def test_bad_actions_are_rejected_and_change_nothing(action, words):
    env = gym.make("SOfAR-LagunaSeca-v0", config=SHORT).unwrapped
    env.reset(seed=0)
    states, t = env.race.states.copy(), env.race.time
    with pytest.raises(ValueError) as info:
        env.step(action)
    for w in words:
        assert w in str(info.value), (w, str(info.value))
    np.testing.assert_array_equal(states, env.race.states)
    assert env.race.time == t
