"""sofar_env.vector: AsyncVectorEnv workers pinned to a CPU each, the main process left alone, results unchanged."""

from __future__ import annotations

import functools
import multiprocessing as mp
import os

import gymnasium as gym
import numpy as np
import pytest

from sofar_env.vector import PinnedFactory, async_vector_env, pinned_factories, worker_cpus

CAN_PIN = hasattr(os, "sched_setaffinity") and len(os.sched_getaffinity(0)) >= 2
needs_two_cpus = pytest.mark.skipif(not CAN_PIN, reason="needs os.sched_setaffinity and 2 CPUs")


class AffinityEnv(gym.Env):
    """A tiny env that can tell which CPUs its process may run on."""

    observation_space = gym.spaces.Box(-1.0, 1.0, (1,), np.float32)
    action_space = gym.spaces.Box(-1.0, 1.0, (1,), np.float32)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        return np.zeros(1, np.float32), {}

    def step(self, action):
        return np.zeros(1, np.float32), 0.0, False, False, {}

    def cpus(self) -> list[int]:
        return sorted(os.sched_getaffinity(0))


def _call_in_child(factory, queue) -> None:
    env = factory()
    queue.put(env.cpus())


@pytest.mark.parametrize("bad", [0, -1])
def test_worker_cpus_rejects_no_workers(bad):
    with pytest.raises(ValueError, match="n_workers"):
        worker_cpus(bad)


def test_worker_cpus_gives_one_cpu_each_or_none():
    if not hasattr(os, "sched_getaffinity"):
        assert worker_cpus(1) is None
        return
    available = sorted(os.sched_getaffinity(0))
    assert worker_cpus(len(available)) == available
    assert worker_cpus(1) == available[:1]
    assert worker_cpus(len(available) + 1) is None  # more workers than CPUs: left to the operating system


def test_factories_bad_input():
    with pytest.raises(ValueError, match="empty"):
        pinned_factories([])
    with pytest.raises(TypeError, match="callable"):
        PinnedFactory("not a factory", 0)


def test_unpinned_factories_are_the_given_ones():
    fns = [AffinityEnv, AffinityEnv]
    assert pinned_factories(fns, pin=False) == fns


@needs_two_cpus
def test_the_factory_pins_a_child_process_but_never_its_maker():
    before = sorted(os.sched_getaffinity(0))
    cpu = before[-1]
    factory = PinnedFactory(AffinityEnv, cpu)
    assert factory().cpus() == before  # called where it was made: the main process stays as it was
    ctx = mp.get_context("spawn")
    queue = ctx.Queue()
    proc = ctx.Process(target=_call_in_child, args=(factory, queue))
    proc.start()
    try:
        assert queue.get(timeout=120) == [cpu]
    finally:
        proc.join(timeout=30)
    assert sorted(os.sched_getaffinity(0)) == before


@needs_two_cpus
def test_async_vector_env_pins_each_worker_to_its_own_cpu():
    before = sorted(os.sched_getaffinity(0))
    envs = async_vector_env([AffinityEnv, AffinityEnv])
    try:
        assert [list(c) for c in envs.call("cpus")] == [[before[0]], [before[1]]]
    finally:
        envs.close()
    assert sorted(os.sched_getaffinity(0)) == before  # gymnasium's dummy env in this process pinned nothing


def _rollout(pin: bool, steps: int = 25) -> tuple[np.ndarray, np.ndarray]:
    from sofar_env.env import SOfARRaceEnv

    factory = functools.partial(SOfARRaceEnv, track="LagunaSeca", rho=0.5, n_opponents=2)
    envs = async_vector_env([factory, factory], pin_workers=pin)
    try:
        obs, _ = envs.reset(seed=[3, 4])
        observations, rewards = [obs], []
        for k in range(steps):
            obs, reward, *_ = envs.step(np.full((2, 1), 0.2 + 0.03 * k, np.float32))
            observations.append(obs)
            rewards.append(reward)
    finally:
        envs.close()
    return np.array(observations), np.array(rewards)


@needs_two_cpus
def test_pinning_changes_where_the_workers_run_not_what_they_compute():
    obs_a, rew_a = _rollout(pin=False)
    obs_b, rew_b = _rollout(pin=True)
    np.testing.assert_array_equal(obs_a, obs_b)
    np.testing.assert_array_equal(rew_a, rew_b)
    assert np.isfinite(obs_a).all() and np.any(rew_a != 0.0)
