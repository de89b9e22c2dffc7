"""The executor's process backend: tasks in worker processes of this machine, one pipe each, one task in flight each.

The driver starts ``n_workers`` :class:`~sofar_agents.worker_processes.WorkerProcess` es (spawn) whose body holds
one runner (``runner_factory()``), and sends each its first task at once: when a result comes back, the worker
gets the next task, in the order of ``pending`` (so a worker mostly meets the environment it has built). Results
go to ``on_result`` in the driver, which alone writes the results file. There is no Manager and no shared queue,
so nothing but the workers can outlive the driver, and a worker that dies loses the one task it was running, not
the rest of the run: the others go on with the remaining tasks, and the lost one is counted (a rerun retries it).

Lifetime (:mod:`sofar_agents.worker_processes`): the workers end with the driver, even when it is killed with
SIGKILL; they ignore SIGINT. On any exception in the driver (Ctrl-C included) they are killed before it
propagates; otherwise they are stopped once the tasks are done.
"""

from __future__ import annotations

import functools
import logging
import traceback
import warnings
from collections.abc import Callable, Sequence
from typing import Any

from sofar_agents.worker_processes import (WorkerFailed, WorkerGone, WorkerProcess, kill_workers, stop_workers,
                                           wait_ready)

__all__ = ["run_processes"]

logger = logging.getLogger(__name__)


class TaskBody:
    """The body of an executor worker: a runner, and ``run`` that never raises for a task that fails.

    ``run(task)`` answers ``(True, payload)`` or ``(False, traceback text)``, so that the transport's own
    failures (a body that could not be built) stay apart from a task's.
    """

    def __init__(self, runner_factory: Callable[[], Any]) -> None:
        warnings.simplefilter("ignore", UserWarning)  # the driver reports failures; keep worker output quiet
        self.runner = runner_factory()

    def run(self, task: Any) -> tuple[bool, Any]:
        try:
            return True, self.runner.run(task)
        except Exception:
            return False, traceback.format_exc()

    def close(self) -> None:
        self.runner.close()


def run_processes(pending: Sequence, runner_factory: Callable[[], Any], on_result: Callable[[int, bool, Any], None],
                  n_workers: int, describe: Callable[[Any], str] = repr) -> int:
    """Run ``pending`` on ``n_workers`` worker processes, calling ``on_result(index, ok, payload)`` here per task.

    Returns the number of tasks that got no result because their worker process died (each logged as an error
    naming it with ``describe(task)``; if every worker died, the tasks never started are counted too). A worker
    whose runner could not be built fails its task (``ok`` False, with the traceback) and gets no other.
    """
    workers: list[WorkerProcess] = []
    in_flight: dict[WorkerProcess, int] = {}  # worker -> index into pending
    next_idx = 0
    lost = 0
    body = functools.partial(TaskBody, runner_factory)

    def dispatch(w: WorkerProcess) -> None:
        nonlocal next_idx
        if next_idx < len(pending):
            try:
                w.call("run", pending[next_idx])
            except WorkerGone:  # nothing was handed to it
                return
            in_flight[w] = next_idx
            next_idx += 1

    try:
        for k in range(n_workers):
            w = WorkerProcess(body, name=f"sofar-worker-{k}")
            workers.append(w)
            dispatch(w)
        while in_flight:
            for w in wait_ready(list(in_flight)):
                idx = in_flight.pop(w)
                try:
                    ok, payload = w.answer()  # ready: an answer, or the end of a worker that died
                except WorkerGone:
                    lost += 1
                    logger.error("worker process %s died (exit code %s) running %s: it is left out of the results, "
                                 "a rerun retries it", w.name, w.exitcode, describe(pending[idx]))
                    continue
                except WorkerFailed as err:  # the body could not be built: this worker is done
                    on_result(idx, False, str(err))
                    continue
                on_result(idx, ok, payload)
                dispatch(w)
        if next_idx < len(pending):
            lost += len(pending) - next_idx
            logger.error("every worker process died: %d %s were not started", len(pending) - next_idx,
                         "tasks" if len(pending) - next_idx != 1 else "task")
    except BaseException:
        kill_workers(workers)
        raise
    stop_workers(workers)
    return lost
