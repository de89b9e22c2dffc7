"""Tasks, results and the executor loop: what every table and replay shares.

Contract (see also the package docstring):

* A **task** is a picklable value with a ``key`` (hashable) that holds every setting that changes its result,
  the configuration hash included, so that a result recorded under another configuration is never taken for it.
* A **job** (:class:`Job`) says how tasks run and where their results go: ``runner`` builds the worker body
  (``runner().run(task) -> payload``, ``close()``) once per worker; ``done_keys()`` are the keys whose results
  its results file already holds (read once, before anything runs); ``write(task, payload, stats)`` records a
  finished task (called in the driver only, in completion order, so only the driver writes the file).
* :func:`execute` runs every task whose key is not done (duplicates once), on a backend, and counts what
  happened in :class:`RunStats`: a task that raised is ``failed`` (logged with its traceback, left out of the
  results, retried by a rerun); a task lost with a worker that died is ``missing`` (logged, retried by a rerun);
  neither raises. On any exception in the driver (Ctrl-C included) the workers are killed before it propagates.
  :func:`incomplete_message` is what a script reports for an incomplete run before it exits with status 1.
"""

from __future__ import annotations

import logging
import os
import time
import traceback
from collections.abc import Callable, Hashable, Sequence
from dataclasses import dataclass, field
from typing import Any

__all__ = ["BACKENDS", "Job", "RunStats", "Runner", "execute", "incomplete_message", "missing_summary"]

logger = logging.getLogger(__name__)

BACKENDS: tuple[str, ...] = ("local", "inline", "processes", "ray")
"""``local``: this machine (in this process with one worker, else worker processes); ``inline``: in this
process; ``processes``: worker processes of this machine (:mod:`~sofar_agents.executor.processes`); ``ray``: Ray
actors, locally or on a cluster (:mod:`~sofar_agents.executor.ray_actors`)."""

Runner = Any
"""A worker body: ``run(task) -> payload`` (picklable) and ``close()``."""

OnResult = Callable[[int, bool, Any], None]
"""``on_result(index into pending, ok, payload or traceback text)``, called by a backend in the driver."""


@dataclass
class RunStats:
    """What a run did."""

    requested: int = 0
    skipped: int = 0
    """Tasks whose results the results file already held."""
    completed: int = 0
    failed: int = 0
    """Tasks that raised (logged with their traceback in ``errors``)."""
    missing: int = 0
    """Tasks that got no result because their worker process died (logged)."""
    elapsed: float = 0.0
    """Wall time of the run [s]."""
    workers: int = 0
    errors: list[str] = field(default_factory=list)

    @property
    def unfinished(self) -> int:
        """Tasks of this run left out of the results (``failed + missing``): a rerun retries them."""
        return self.failed + self.missing


class Job:
    """How a list of tasks runs and where its results go (module docstring); subclasses override what they need.

    ``unit`` names the tasks in messages (plural, e.g. ``"episodes"``); ``runner`` is a picklable zero-argument
    callable that builds one worker body.
    """

    unit: str = "tasks"
    runner: Callable[[], Runner]

    def done_keys(self) -> set[Hashable]:
        """Keys of the tasks whose results are already recorded (default: none)."""
        return set()

    def order(self, pending: list) -> list:
        """The order in which the pending tasks are handed out (default: as given)."""
        return pending

    def open(self, pending: Sequence) -> None:
        """Called once before the first of ``pending`` runs (open the results file, warm up)."""

    def write(self, task: Any, payload: Any, stats: RunStats) -> None:
        """Record the result of a finished task (driver only)."""
        raise NotImplementedError

    def close(self) -> None:
        """Called once after the run, also when it raised (close the results file)."""

    def describe(self, task: Any) -> str:
        """The task in log messages."""
        return f"task {task.key}"

    def postfix(self, stats: RunStats) -> dict[str, Any]:
        """Extra fields of the progress bar."""
        return {}


def _progress_bar(total: int, enabled: bool, unit: str):
    from tqdm.auto import tqdm

    return tqdm(total=total, unit=unit, desc=unit, disable=not enabled, dynamic_ncols=True, smoothing=0.05)


def run_inline(pending: Sequence, runner_factory: Callable[[], Runner], on_result: OnResult) -> int:
    """The in-process backend: one body in this process runs ``pending`` in order; returns 0 (nothing is lost)."""
    runner = runner_factory()
    try:
        for i, task in enumerate(pending):
            try:
                payload = runner.run(task)
            except Exception:
                on_result(i, False, traceback.format_exc())
                continue
            on_result(i, True, payload)
    finally:
        runner.close()
    return 0


def check_workers(workers: int | None, backend: str, address: str | None = None) -> None:
    """``ValueError`` for an unknown backend, an address without Ray or fewer than one worker (None: one per CPU)."""
    if backend not in BACKENDS:
        raise ValueError(f"unknown backend {backend!r} (expected one of {', '.join(BACKENDS)})")
    if address is not None and backend != "ray":
        raise ValueError("address (a Ray cluster) needs backend='ray'")
    if workers is not None and int(workers) < 1:  # 0 is not "unset": None is
        raise ValueError(f"workers must be >= 1 (or None: one per CPU), got {workers!r}")


def execute(tasks: Sequence, job: Job, *, workers: int | None = None, backend: str = "local",
            address: str | None = None, progress: bool = True, stats: RunStats | None = None) -> RunStats:
    """Run every task of ``tasks`` not in ``job.done_keys()`` and record each result with ``job.write``.

    ``workers``: None for one per CPU, below 1 raises ``ValueError`` (before anything is read or run); at most one
    per pending task. ``backend``: one of :data:`BACKENDS`; ``address`` (``"auto"``, ``"HOST:6379"``) joins a Ray
    cluster (``backend="ray"`` only; without Ray installed an ImportError says how to install it, before anything
    is read). ``stats``: a :class:`RunStats` (or subclass) to fill, e.g. one that ``job.write`` adds to.
    Returns the stats; an incomplete run (``stats.unfinished``) does not raise (module docstring).
    """
    check_workers(workers, backend, address)
    if backend == "ray":
        from sofar_agents.ray_support import require_ray

        require_ray(local=address is None)  # fail before reading anything if Ray is missing
    t_start = time.perf_counter()
    stats = stats if stats is not None else RunStats()
    done = job.done_keys()
    pending, seen = [], set()
    for t in tasks:
        if t.key not in done and t.key not in seen:
            pending.append(t)
            seen.add(t.key)
    stats.requested, stats.skipped = len(tasks), len(tasks) - len(pending)
    if not pending:
        stats.elapsed = time.perf_counter() - t_start
        return stats
    pending = job.order(pending)
    n_workers = max(1, min(int(workers or os.cpu_count() or 1), len(pending)))
    stats.workers = n_workers  # the Ray backend replaces it with its number of actors
    bar = None
    try:
        job.open(pending)
        bar = _progress_bar(len(pending), progress, job.unit)

        def on_result(idx: int, ok: bool, payload: Any) -> None:
            task = pending[idx]
            if ok:
                job.write(task, payload, stats)
                stats.completed += 1
                bar.set_postfix(**job.postfix(stats), failed=stats.failed, refresh=False)
            else:
                stats.failed += 1
                stats.errors.append(payload)
                logger.error("%s failed:\n%s", job.describe(task), payload)
            bar.update(1)

        if backend == "inline" or (backend == "local" and n_workers == 1):
            run_inline(pending, job.runner, on_result)
        elif backend == "ray":
            from sofar_agents.executor.ray_actors import run_on_ray

            stats.workers = run_on_ray(pending, job.runner, on_result, workers=workers, address=address)
        else:
            from sofar_agents.executor.processes import run_processes

            stats.missing = run_processes(pending, job.runner, on_result, n_workers, describe=job.describe)
    finally:
        if bar is not None:
            bar.close()
        job.close()
        stats.elapsed = time.perf_counter() - t_start
    return stats


def missing_summary(stats: RunStats, unit: str = "tasks") -> str | None:
    """``"N of M <unit> are missing (F failed, L lost with a worker process that died)"``, or None when none is."""
    if not stats.unfinished:
        return None
    why = []
    if stats.failed:
        why.append(f"{stats.failed} failed")
    if stats.missing:
        why.append(f"{stats.missing} lost with a worker process that died")
    return f"{stats.unfinished} of {stats.requested} {unit} are missing ({', '.join(why)})"


def incomplete_message(stats: RunStats, out: str | os.PathLike, unit: str = "episodes") -> str | None:
    """What a script reports for a run that left tasks out of its results, or None if it did not.

    Says how many are missing, why (failed, or lost with a worker process that died), and that re-running the
    same command with the same ``out`` folder resumes: the results keep the finished tasks and only the missing
    ones run. Scripts log it as an error and exit with status 1.
    """
    summary = missing_summary(stats, unit)
    if summary is None:
        return None
    return (f"incomplete: {summary}; re-run with the same --out {out} to resume (the finished {unit} are kept, "
            f"only the missing ones run)")
