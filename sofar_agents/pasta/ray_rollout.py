"""PASTA rollouts on Ray: the envs (and their solvers) live in Ray actors, the learner in the driver.

:class:`RayEnvPool` is the :class:`~sofar_agents.pasta.actor_pool.ActorEnvPool` whose actors are Ray
actors (one CPU each), on this machine or on a Ray cluster. How a rollout is collected, and why a
seeded run equals the local backend's bit for bit, is in :mod:`sofar_agents.pasta.actor_pool`.

The actors are started as the executor's are (:mod:`sofar_agents.ray_support`: Ray started or joined in one place,
each actor tied to the driver's process, so a learner killed with SIGKILL leaves no rollout actor behind), but
they are stateful and never restarted: a dead actor fails the rollout (why: docs/decisions/one-executor.md).
"""

from __future__ import annotations

import copy
from collections.abc import Callable, Sequence
from typing import Any

from sofar_agents.pasta.actor_pool import ActorEnvPool, EnvSlice
from sofar_agents.ray_support import DriverIdentity, driver_identity, follow_driver, init_ray, require_ray

__all__ = ["RayEnvPool", "init_ray"]


class _RaySlice(EnvSlice):
    """The actor body: an :class:`EnvSlice` that ends with the driver's process (``driver``, on the same node)."""

    def __init__(self, make_vector: Callable[[], Any], start: int, n_total: int, driver: DriverIdentity | None) -> None:
        follow_driver(driver)
        super().__init__(make_vector, start, n_total)


class RayEnvPool(ActorEnvPool):
    """``n_envs`` training envs in ``num_workers`` Ray actors, used by :meth:`PASTA.learn` like a vector env.

    Args:
        env_fns: one picklable zero-argument env factory per env (e.g.
            ``functools.partial(make_training_env, ...)``); env i is seeded like env i of
            a local vector env.
        num_workers: Ray actors (one CPU each); the envs are split into contiguous slices.
        address: ``None`` starts a local Ray instance with ``num_workers`` CPUs (unless Ray
            is already initialised); ``"auto"`` or ``"HOST:PORT"`` joins a running cluster.
        chunk_steps: steps an actor runs per call (the waits for preference draws are at
            most one chunk long); it does not change the result.
        cars_per_race: ``env_fns`` build PettingZoo races of this many cars (self-play); None: gymnasium envs.
    """

    worker_label = "Ray rollout worker"

    def __init__(self, env_fns: Sequence[Callable[[], Any]], num_workers: int, address: str | None = None,
                 chunk_steps: int = 64, cars_per_race: int | None = None) -> None:
        super().__init__(env_fns, num_workers, chunk_steps, cars_per_race)
        self._ray = require_ray(local=address is None)
        self._started = init_ray(address, num_workers)
        actor_cls = self._ray.remote(num_cpus=1, max_restarts=0)(_RaySlice)
        driver = driver_identity()
        self.actors = [actor_cls.remote(fn, lo, self.num_envs, driver)
                       for fn, (lo, _) in zip(self._vector_fns, self.slices)]
        self._describe()
        # deep copies: arrays that Ray deserialises are read-only
        self.single_observation_space = copy.deepcopy(self.single_observation_space)
        self.single_action_space = copy.deepcopy(self.single_action_space)

    def _submit(self, w: int, method: str, *args: Any) -> Any:
        return getattr(self.actors[w], method).remote(*args)

    def _wait_any(self, handles: list) -> Any:
        ready, _ = self._ray.wait(handles, num_returns=1)
        return ready[0]

    def _result(self, w: int, handle: Any) -> Any:
        return self._ray.get(handle)

    def _share(self, obj: Any) -> Any:
        return self._ray.put(obj)

    def close(self) -> None:
        """Kill the actors (and shut down Ray if this pool started it)."""
        for actor in self.actors:
            self._ray.kill(actor, no_restart=True)
        self.actors = []
        self.closed = True
        if self._started and self._ray.is_initialized():
            self._ray.shutdown()
        self._started = False
