"""Copies of running environments (``copy.deepcopy``, pickle, cloudpickle) and ``get_state()`` / ``set_state()``:
each continues to the bit like the original under the same actions, without compiling anything."""

from __future__ import annotations

import copy
import pickle

import cloudpickle
import gymnasium as gym
import numpy as np
import pytest

import sofar_env
from sofar_env.registration import DYNAMIC_IDS, ENV_IDS, INTERACTIVE_IDS
from sofar_env.snapshot import EnvState

STEPS = 200
WORLDS = {"paper": ENV_IDS[0], "interactive": INTERACTIVE_IDS[0], "dynamic": DYNAMIC_IDS[0]}


def _trace(env, actions) -> list[bytes]:
    """Every step's (observation, reward, terminated, truncated, info) as bytes; resets after an episode end."""
    out = []
    for k, a in enumerate(actions):
        step = env.step(a)
        out.append(pickle.dumps(step))
        if step[2] is True or step[3] is True:
            env.reset(seed=k)
    return out


def _compiled_now(env) -> bool:
    return env.unwrapped.stack.mpc._lin.codegen_info.built_now


@pytest.mark.parametrize("world", sorted(WORLDS))
def test_copies_and_restored_states_continue_bit_identically(world):
    env = gym.make(WORLDS[world], reward_mode="vector")
    env.reset(seed=2)
    rng = np.random.default_rng(7)
    for a in rng.uniform(0.05, 1.0, (15, 1)).astype(np.float32):
        env.step(a)
    copies = {"deepcopy": copy.deepcopy(env), "pickle": pickle.loads(pickle.dumps(env)),
              "cloudpickle": cloudpickle.loads(cloudpickle.dumps(env))}
    state = env.unwrapped.get_state()
    actions = rng.uniform(0.05, 1.0, (STEPS, 1)).astype(np.float32)
    expected = _trace(env, actions)
    for how, other in copies.items():
        assert not _compiled_now(other), how
        assert _trace(other, actions) == expected, how
    env.unwrapped.set_state(state)
    assert _trace(env, actions) == expected  # back to the saved moment
    env.unwrapped.set_state(pickle.loads(pickle.dumps(state)))  # a state is reusable and picklable
    assert _trace(env, actions[:20]) == expected[:20]


def test_set_state_on_another_env_with_the_same_arguments():
    env = gym.make(ENV_IDS[1], reward_mode="vector")
    env.reset(seed=0)
    for _ in range(5):
        env.step(np.array([0.4], np.float32))
    state = env.unwrapped.get_state()
    actions = np.linspace(0.1, 0.9, 20, dtype=np.float32).reshape(-1, 1)
    expected = _trace(env, actions)
    other = gym.make(ENV_IDS[1], reward_mode="vector")
    other.reset(seed=99)  # gymnasium's order enforcement wants a reset before a step
    other.unwrapped.set_state(state)
    assert other.unwrapped.track is not env.unwrapped.track  # the state's circuit is replaced by the env's own
    assert other.unwrapped.race.track is other.unwrapped.track
    assert _trace(other, actions) == expected


@pytest.mark.parametrize("bad", ["other circuit", "other config", "not a state", "parallel env"])
def test_set_state_of_another_env_raises_and_changes_nothing(bad):
    env = gym.make(ENV_IDS[0], reward_mode="vector")
    env.reset(seed=1)
    env.step(np.array([0.5], np.float32))
    if bad == "not a state":
        state = {"core": None}
    elif bad == "parallel env":
        race = sofar_env.parallel_env(track="LagunaSeca", n_agents=1)
        state = race.get_state()
    else:
        kwargs = {"other circuit": {"id": ENV_IDS[1]}, "other config": {"id": ENV_IDS[0], "rho": 0.7}}[bad]
        donor = gym.make(kwargs.pop("id"), reward_mode="vector", **kwargs)
        donor.reset(seed=1)
        state = donor.unwrapped.get_state()
    twin = copy.deepcopy(env)
    core = env.unwrapped.core
    with pytest.raises(ValueError, match="state"):
        env.unwrapped.set_state(state)
    assert env.unwrapped.core is core
    actions = np.full((5, 1), 0.3, np.float32)
    assert _trace(env, actions) == _trace(twin, actions)


def test_get_state_before_the_first_reset_and_a_rendering_env_pickles():
    env = gym.make(ENV_IDS[0], render_mode="rgb_array", race={"duration": 2.0})
    state = env.unwrapped.get_state()
    assert isinstance(state, EnvState) and not state.parts["core"].built
    env.reset(seed=0)
    env.step(np.array([0.5], np.float32))
    assert env.render().ndim == 3
    other = pickle.loads(pickle.dumps(env))
    assert other.unwrapped._renderer is None  # made again by the next render()
    a = np.array([0.6], np.float32)
    assert pickle.dumps(env.step(a)) == pickle.dumps(other.step(a))
    assert other.render().shape == env.render().shape
    env.unwrapped.set_state(state)  # back to before the first reset
    assert not env.unwrapped.core.built


def test_parallel_race_copies_and_states_continue_bit_identically():
    env = sofar_env.parallel_env(track="LagunaSeca", n_agents=3, reward_mode="vector")
    env.reset(seed=4)
    rng = np.random.default_rng(3)

    def actions(n):
        return [{a: rng.uniform(0.05, 1.0, 1).astype(np.float32) for a in env.possible_agents} for _ in range(n)]

    def trace(race, acts):
        out = []
        for a in acts:
            if not race.agents:
                break
            out.append(pickle.dumps(race.step({k: a[k] for k in race.agents})))
        return out

    trace(env, actions(15))
    copies = [copy.deepcopy(env), pickle.loads(pickle.dumps(env)), cloudpickle.loads(cloudpickle.dumps(env))]
    state = env.get_state()
    acts = actions(STEPS)
    expected = trace(env, acts)
    assert len(expected) > 100
    for other in copies:
        assert not any(s.mpc._lin.codegen_info.built_now for s in other.stacks)
        assert trace(other, acts) == expected
    env.set_state(state)
    assert trace(env, acts) == expected
