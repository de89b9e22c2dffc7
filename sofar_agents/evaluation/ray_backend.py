"""Ray backend of the sweeps: run episodes in Ray actors on one machine or a cluster.

Each actor (one CPU) owns an episode runner, so it builds the environment and policy
of a track/configuration once and reuses them for later episodes. The driver keeps one
episode in flight per actor and hands every result to the caller's ``handle`` (which
writes the CSV row), so results are written by the driver only. A task on an actor
whose process dies is retried on the restarted actor (``max_task_retries``); if the
retries are exhausted the episode is reported as failed and a rerun of the sweep
retries it.

The actors end with the driver: Ray ends a job's actors when its driver exits, and an actor on
the driver's machine also watches the driver's process
(:func:`~sofar_agents.worker_lifetime.exit_with_process`), so a driver killed with SIGKILL does not
leave busy actors behind. The other processes of a local Ray instance are Ray's own: its GCS and
raylet end with the driver, its agents follow the raylet within about a minute.

``address=None`` starts a local Ray instance with ``workers`` CPUs; ``"auto"`` or
``"HOST:6379"`` joins a running cluster (``ray start --head``), and then every node
must have this package installed (``pip install "sofar[ray]"``), as the actors import
it. Ray is imported lazily: without it, :func:`require_ray` raises an ImportError that
says how to install it.
"""

from __future__ import annotations

import logging
import os
import traceback
import warnings
from collections.abc import Callable, Sequence

from sofar_agents.evaluation.protocol import EpisodeTask
from sofar_agents.evaluation.runner import EpisodeRunner as _EpisodeRunner
from sofar_agents.ray_support import INSTALL_HINT, init_ray, require_ray  # noqa: F401  (re-exported)
from sofar_agents.worker_lifetime import exit_with_process, process_start_time

logger = logging.getLogger(__name__)

MAX_TASK_RETRIES = 3
"""Times an episode is retried after its actor's process died."""


class _RunnerActor:
    """Actor body: runs episodes with its own (cached) environments and policies.

    ``driver``: ``(Ray node id, pid, start time)`` of the driver; an actor on the same node ends
    its process as soon as the driver's process has ended.
    """

    def __init__(self, runner_cls: type, driver: tuple[str, int, str | None] | None = None) -> None:
        warnings.simplefilter("ignore", UserWarning)  # the driver reports failures; keep worker output quiet
        if driver is not None:
            import ray

            node_id, pid, start_time = driver
            if ray.get_runtime_context().get_node_id() == node_id:
                exit_with_process(pid, start_time)
        self.runner = runner_cls()

    def run(self, idx: int, task: EpisodeTask) -> tuple:
        try:
            result, trace = self.runner.run(task)
            return ("ok", idx, result.to_row(), trace)
        except Exception:
            return ("error", idx, traceback.format_exc(), None)


def run_ray(pending: Sequence[EpisodeTask], handle: Callable, *, workers: int | None = None,
            address: str | None = None) -> int:
    """Run ``pending`` on Ray actors, calling ``handle(msg)`` in the driver for every finished episode.

    ``msg`` is ``(status, index into pending, row or traceback, trace)`` as for the process pool.
    Uses an already initialised Ray (and leaves it running); otherwise starts or joins one
    (see the module docstring) and shuts it down at the end. Returns the number of actors.
    """
    ray = require_ray(local=address is None)
    started = init_ray(address, int(workers or os.cpu_count() or 1))
    actors: list = []
    try:
        n_cpus = int(ray.cluster_resources().get("CPU", 1))
        n_actors = max(1, min(int(workers or n_cpus), len(pending)))
        actor_cls = ray.remote(num_cpus=1, max_restarts=-1, max_task_retries=MAX_TASK_RETRIES)(_RunnerActor)
        driver = (ray.get_runtime_context().get_node_id(), os.getpid(), process_start_time(os.getpid()))
        actors = [actor_cls.remote(_EpisodeRunner, driver) for _ in range(n_actors)]
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
                msg = ray.get(ref)
            except Exception as exc:  # the actor died more often than the retries allow
                msg = ("error", idx, f"Ray task lost: {exc!r}", None)
            handle(msg)
            submit(actor)
        return n_actors
    finally:
        for actor in actors:
            ray.kill(actor, no_restart=True)
        if started:
            ray.shutdown()
