"""The episode life cycle of both adapters: a failed reset, a step outside an episode, the PettingZoo arguments.

Item 10: a failed first ``reset()`` leaves a ``gymnasium.make`` env resettable, and ``step()`` before a successful
reset raises a clear error and changes nothing. Item 11: ``step()`` after the episode ended refuses (a
``RuntimeError`` saying to call ``reset()``) and changes nothing, in both adapters. Item 17: PettingZoo's
``n_agents`` must be an integer >= 1, and actions for agents not in the race are errors.
"""

import math
import warnings

import gymnasium as gym
import numpy as np
import pytest

import sofar_env  # noqa: F401  (registers the ids)
from sofar_env.errors import ConfigError, ResetNeeded
from sofar_env.multi_agent import parallel_env

GAMMA = np.array([0.5], np.float32)


def _world(env) -> tuple:
    """What a refused call must not change: time, the cars' states, the opponents, the generator (None: no world
    has been built, a circuit that refused the configuration)."""
    race = env.race
    if race is None:
        return None
    rng = getattr(env, "np_random", None) if isinstance(env, gym.Env) else env._np_random
    return (race.time, race.steps, race.states.copy(), race.opponents.s.copy(), race.opponents.n.copy(),
            None if rng is None else str(rng.bit_generator.state))


def _assert_same(before: tuple | None, after: tuple | None) -> None:
    if before is None or after is None:
        assert before is after
        return
    assert before[:2] == after[:2] and before[5] == after[5]
    for a, b in zip(before[2:5], after[2:5]):
        np.testing.assert_array_equal(a, b)


# ---------------------------------------------------------------------------------------------- item 10
@pytest.mark.parametrize("env_id, kwargs, bad_options, recoverable", [
    ("SOfAR-LagunaSeca-v0", {}, {"rho": 5.0}, True),
    ("SOfAR-LagunaSeca-v0", {}, {"n_opponents": 400}, True),
    ("SOfAR-Monza-Interactive-v0", {}, {"start_speed": -1.0}, True),
    ("SOfAR-LagunaSeca-v0", {"reward_mode": "vector"}, {"start_s": math.nan}, True),
    ("SOfAR-LagunaSeca-v0", {"offsets": (20.0,)}, {}, False),  # a configuration only the circuit can refuse
])
def test_a_failed_first_reset_leaves_the_env_resettable(env_id, kwargs, bad_options, recoverable):
    env = gym.make(env_id, config={"race": {"duration": 3.0}}, **kwargs)
    for _ in range(2):  # failing twice changes nothing either
        with pytest.raises(ValueError):
            env.reset(seed=0, options=bad_options)
    before = _world(env.unwrapped)
    for _ in range(2):
        with pytest.raises(RuntimeError, match=r"call reset\(\)") as info:
            env.step(GAMMA)
        assert isinstance(info.value, (ResetNeeded, gym.error.ResetNeeded))
    _assert_same(before, _world(env.unwrapped))
    if not recoverable:
        with pytest.raises(ValueError):
            env.reset(seed=0)
        return
    twin = gym.make(env_id, config={"race": {"duration": 3.0}}, **kwargs)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # nor a warning of the passive checker
        obs, _ = env.reset(seed=0)
        twin_obs, _ = twin.reset(seed=0)
        np.testing.assert_array_equal(obs, twin_obs)
        for _ in range(3):  # the same episode, to the bit, without the checker's TypeError
            np.testing.assert_array_equal(env.step(GAMMA)[0], twin.step(GAMMA)[0])
    env.close()
    twin.close()


# ---------------------------------------------------------------------------------------------- item 11
def _single(env_id, **kwargs):
    env = gym.make(env_id, **kwargs)

    def run_to_the_end():
        env.reset(seed=3)
        for n in range(1, 1000):
            _, _, terminated, truncated, _ = env.step(GAMMA)
            if terminated or truncated:
                return n
        raise AssertionError("the episode did not end")

    return env, run_to_the_end, lambda: env.step(GAMMA)


def _multi(**kwargs):
    env = parallel_env(track="LagunaSeca", n_agents=2, speed_factors=(0.8, 0.85), **kwargs)

    def run_to_the_end():
        env.reset(seed=3)
        for n in range(1, 1000):
            env.step({a: GAMMA for a in env.agents})
            if not env.agents:
                return n
        raise AssertionError("the episode did not end")

    return env, run_to_the_end, lambda: env.step({})


@pytest.mark.parametrize("make, steps", [
    (lambda: _single("SOfAR-LagunaSeca-v0", race={"duration": 0.3}), 3),  # truncated
    (lambda: _single("SOfAR-LagunaSeca-v0", race={"duration": 0.6}, decision_interval=2), 3),
    (lambda: _single("SOfAR-Monza-Interactive-v0", stall_speed=1000.0, stall_seconds=0.1), 1),  # terminated
    (lambda: _single("SOfAR-LagunaSeca-v0", race={"duration": 0.3}, reward_mode="vector"), 3),
    (lambda: _multi(race={"duration": 0.3}), 3),
    (lambda: _multi(stall_speed=1000.0, stall_seconds=0.1), 1),
])
def test_step_after_the_end_refuses_and_changes_nothing(make, steps):
    env, run_to_the_end, step = make()
    assert run_to_the_end() == steps
    before = _world(env.unwrapped)
    for _ in range(2):
        with pytest.raises(RuntimeError, match=r"episode has ended.*call reset\(\)"):
            step()
    _assert_same(before, _world(env.unwrapped))
    assert run_to_the_end() == steps  # a reset starts the next episode as usual
    env.close()


def test_pettingzoo_step_after_the_end_refuses_whatever_the_actions():
    env, run_to_the_end, _ = _multi(race={"duration": 0.2})
    run_to_the_end()
    for actions in ({}, {"car_0": GAMMA, "car_1": GAMMA}):
        with pytest.raises(ResetNeeded):
            env.step(actions)


def test_pettingzoo_step_before_reset_refuses():
    env = parallel_env(track="LagunaSeca", n_agents=2)
    with pytest.raises(ResetNeeded, match="no reset"):
        env.step({"car_0": GAMMA, "car_1": GAMMA})


# ---------------------------------------------------------------------------------------------- item 17
@pytest.mark.parametrize("n_agents", [2.7, "3", True, False, 0, -1, None, 2.0, np.float64(2.0), np.bool_(True)])
def test_n_agents_must_be_an_integer_of_at_least_one(n_agents):
    with pytest.raises(ConfigError, match="n_agents must be an integer >= 1"):
        parallel_env(track="LagunaSeca", n_agents=n_agents)


@pytest.mark.parametrize("n_agents", [1, 2, np.int64(2)])
def test_integer_n_agents_are_accepted(n_agents):
    env = parallel_env(track="LagunaSeca", n_agents=n_agents)
    assert env.possible_agents == [f"car_{i}" for i in range(int(n_agents))]


def _stalled_car_1():
    """A 2-car race in which car_1 (a crawling speed reference) stalls and leaves at the 25th step."""
    env = parallel_env(track="LagunaSeca", n_agents=2, speed_factors=(0.9, 0.02), stall_speed=3.0, stall_seconds=0.3)
    env.reset(seed=0)
    while env.agents == ["car_0", "car_1"]:
        env.step({a: GAMMA for a in env.agents})
    assert env.agents == ["car_0"]
    return env


@pytest.mark.parametrize("extra, words", [
    ({"car_2": GAMMA}, ["unknown agent", "car_2"]),
    ({"car_9": GAMMA, "bogus": GAMMA}, ["unknown agent", "car_9", "bogus"]),
    ({0: GAMMA}, ["unknown agent", "0"]),
    ({"car_1": GAMMA}, ["car_1", "terminated or been truncated"]),
])
def test_actions_for_agents_not_in_the_race_are_errors(extra, words):
    env = _stalled_car_1()
    before = _world(env)
    with pytest.raises(ValueError) as info:
        env.step({"car_0": GAMMA, **extra})
    for w in words:
        assert w in str(info.value), str(info.value)
    _assert_same(before, _world(env))
    env.step({"car_0": GAMMA})  # the race goes on
    assert env.race.steps == before[1] + 1
