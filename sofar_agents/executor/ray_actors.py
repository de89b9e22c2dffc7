"""The executor's Ray backend: tasks in Ray actors on one machine or a cluster.

Each actor (one CPU) owns a runner (``runner_factory()``), so it builds the environments and policies of a
configuration once and reuses them for later tasks. The driver keeps one task in flight per actor and hands
every result to ``on_result`` (which writes the results file), so results are written by the driver only. A
task on an actor whose process dies is retried on the restarted actor (:data:`MAX_TASK_RETRIES`); if the retries
are exhausted the task is reported as failed, and a rerun retries it.

The actors end with the driver: Ray ends a job's actors when its driver exits, and an actor on the driver's
machine also watches the driver's process (:func:`~sofar_agents.ray_support.follow_driver`, as the training
pool's actors do), so a driver killed with SIGKILL does not leave busy actors behind. The other processes of a local Ray instance are Ray's
own: its GCS and raylet end with the driver, its agents follow the raylet within about a minute.

``address=None`` starts a local Ray instance with ``workers`` CPUs; ``"auto"`` or ``"HOST:6379"`` joins a running
cluster (``ray start --head``), and then every node must have this package installed (``pip install
"sofar[ray]"``), as the actors import it. Ray is imported lazily (:mod:`sofar_agents.ray_support`).
"""

from __future__ import annotations

import logging
import os
import traceback
import warnings
from collections.abc import Callable, Sequence
from typing import Any

from sofar_agents.ray_support import DriverIdentity, driver_identity, follow_driver, init_ray, require_ray

__all__ = ["MAX_TASK_RETRIES", "run_on_ray"]

logger = logging.getLogger(__name__)

MAX_TASK_RETRIES = 3
"""Times a task is retried after its actor's process died."""


class _RunnerActor:
    """Actor body: runs tasks with its own runner.

    ``driver``: the driver's :func:`~sofar_agents.ray_support.driver_identity`; an actor on the same node ends its
    process as soon as the driver's process has ended.
    """

    def __init__(self, runner_factory: Callable[[], Any], driver: DriverIdentity | None = None) -> None:
        warnings.simplefilter("ignore", UserWarning)  # the driver reports failures; keep worker output quiet
        follow_driver(driver)
        self.runner = runner_factory()

    def run(self, idx: int, task: Any) -> tuple[int, bool, Any]:
        try:
            return idx, True, self.runner.run(task)
        except Exception:
            return idx, False, traceback.format_exc()


def run_on_ray(pending: Sequence, runner_factory: Callable[[], Any], on_result: Callable[[int, bool, Any], None], *,
               workers: int | None = None, address: str | None = None) -> int:
    """Run ``pending`` on Ray actors, calling ``on_result(index, ok, payload)`` in the driver for every task.

    Uses an already initialised Ray (and leaves it running); otherwise starts or joins one (module docstring)
    and shuts it down at the end. The actors are killed at the end, also when this raises (Ctrl-C included).
    Returns the number of actors.
    """
    ray = require_ray(local=address is None)
    started = init_ray(address, int(workers or os.cpu_count() or 1))
    actors: list = []
    try:
        n_cpus = int(ray.cluster_resources().get("CPU", 1))
        n_actors = max(1, min(int(workers or n_cpus), len(pending)))
        actor_cls = ray.remote(num_cpus=1, max_restarts=-1, max_task_retries=MAX_TASK_RETRIES)(_RunnerActor)
        driver = driver_identity()
        actors = [actor_cls.remote(runner_factory, driver) for _ in range(n_actors)]
        in_flight: dict = {}
        next_idx = 0

        def submit(actor) -> None:
            nonlocal next_idx
            if next_idx < len(pending):
                in_flight[actor.run.remote(next_idx, pending[next_idx])] = (actor, next_idx)
                next_idx += 1

        for actor in actors:
            submit(actor)
        while in_flight:
            ready, _ = ray.wait(list(in_flight), num_returns=1)
            ref = ready[0]
            actor, idx = in_flight.pop(ref)
            try:
                _, ok, payload = ray.get(ref)
            except Exception as exc:  # the actor died more often than the retries allow
                ok, payload = False, f"Ray task lost: {exc!r}"
            on_result(idx, ok, payload)
            submit(actor)
        return n_actors
    finally:
        for actor in actors:
            ray.kill(actor, no_restart=True)
        if started:
            ray.shutdown()
