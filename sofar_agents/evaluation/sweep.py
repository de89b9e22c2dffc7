"""Sweeps: run a list of episodes on the executor (:mod:`sofar_agents.executor`), appending each result to a CSV.

Table I and II are jobs of the one executor: the episodes run in this process (one worker), in worker processes
(``backend="local"``) or in Ray actors (``backend="ray"``); workers build their environments and policies lazily
(:class:`~sofar_agents.evaluation.runner.EpisodeRunner`) and keep them for later episodes of the same
track/configuration, and end with this process, even when it is killed. Only this process writes the CSV: each
finished episode is appended (flushed), and the episodes already in it (by resume key, which holds the
configuration hash) are skipped, so an interrupted sweep resumes where it stopped. An episode that failed or was
lost with a worker is counted in :class:`SweepStats` (``failed``, ``missing``): the caller decides whether an
incomplete sweep is an error (:func:`incomplete_message`).
"""

from __future__ import annotations

import logging
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass

from sofar_agents.evaluation.protocol import EpisodeTask
from sofar_agents.evaluation.results import EPISODE_COLUMNS, TRACE_COLUMNS, _AppendingCSV, _row_key, read_episode_csv
from sofar_agents.evaluation.runner import EpisodeRunner as _EpisodeRunner
from sofar_agents.executor import Job, RunStats, execute, incomplete_message

__all__ = ["SweepStats", "incomplete_message", "run_sweep"]

logger = logging.getLogger(__name__)


@dataclass
class SweepStats(RunStats):
    """What a sweep did (:class:`~sofar_agents.executor.RunStats`, with the episodes' steps and wall time)."""

    steps: int = 0
    """Control steps simulated by the completed episodes."""
    episode_wall_time: float = 0.0
    """Sum of the episodes' wall times [s] (about workers x elapsed)."""

    @property
    def steps_per_second_per_worker(self) -> float:
        return self.steps / self.episode_wall_time if self.episode_wall_time > 0 else math.nan

    def estimate_hours(self, total_steps: float, workers: int) -> float:
        """Wall hours for ``total_steps`` control steps on ``workers`` workers at the measured speed."""
        rate = self.steps_per_second_per_worker
        return total_steps / (rate * max(workers, 1)) / 3600.0 if rate > 0 else math.nan


class EpisodeJob(Job):
    """Table I / II episodes as an executor job: results in the per-episode CSV (and the trace CSV, if given).

    The runner (``runner``, an :class:`~sofar_agents.evaluation.runner.EpisodeRunner` class) answers
    ``(EpisodeResult, trace rows)``; the row written is ``result.to_row()``.
    """

    unit = "episodes"

    def __init__(self, csv_path: str | os.PathLike, trace_path: str | os.PathLike | None = None,
                 runner: type = _EpisodeRunner) -> None:
        self.csv_path, self.trace_path, self.runner = csv_path, trace_path, runner
        self._out = self._trace = None

    def done_keys(self) -> set:
        return {_row_key(r) for r in read_episode_csv(self.csv_path)}

    def order(self, pending: list) -> list:
        return sorted(pending, key=lambda t: (t.env_key, t.strategy.name))  # workers mostly meet built envs

    def open(self, pending: Sequence[EpisodeTask]) -> None:
        self._out = _AppendingCSV(self.csv_path, EPISODE_COLUMNS)
        self._trace = _AppendingCSV(self.trace_path, TRACE_COLUMNS) if self.trace_path is not None else None
        from sofar_env.compile import warm_up

        warm_up(sorted({t.scenario for t in pending}), multi_agent=False)  # compile here, not inside the bar's ETA

    def write(self, task: EpisodeTask, payload, stats: SweepStats) -> None:
        result, trace = payload
        row = result.to_row()
        self._out.write(row)
        if self._trace is not None and trace:
            self._trace.write_many(trace)
        stats.steps += int(row["steps"])
        stats.episode_wall_time += float(row["wall_time"])

    def postfix(self, stats: SweepStats) -> dict:
        rate = stats.steps / stats.episode_wall_time if stats.episode_wall_time > 0 else 0.0
        return {"steps_per_s": f"{rate * max(stats.workers, 1):.0f}"}

    def close(self) -> None:
        for f in (self._out, self._trace):
            if f is not None:
                f.close()

    def describe(self, task: EpisodeTask) -> str:
        return f"episode {task.track}/{task.strategy.name} rho={task.rho:g} seed={task.seed:d}"


def run_sweep(tasks: Sequence[EpisodeTask], csv_path: str | os.PathLike, *, workers: int | None = None,
              trace_path: str | os.PathLike | None = None, progress: bool = True, backend: str = "local",
              address: str | None = None) -> SweepStats:
    """Run every task not yet in ``csv_path``, appending one row per finished episode.

    ``backend="local"``: ``workers`` processes (None: ``os.cpu_count()``; 1 runs in this
    process; below 1 raises ValueError). ``backend="ray"``: ``workers`` Ray actors (default: the CPUs of the Ray instance)
    on a local Ray instance, or on the cluster at ``address`` (``"auto"`` or ``"HOST:6379"``);
    see :mod:`~sofar_agents.executor.ray_actors`. Either way only this process writes the
    CSV, and no worker outlives it. A failed episode (``stats.failed``) or one lost with a worker
    process that died (``stats.missing``) is logged and left out of the CSV, so the next run
    retries it; check ``stats.unfinished`` to treat an incomplete sweep as an error.
    """
    if backend not in ("local", "ray"):
        raise ValueError(f"unknown sweep backend {backend!r} (expected 'local' or 'ray')")
    job = EpisodeJob(csv_path, trace_path, _EpisodeRunner)
    return execute(tasks, job, workers=workers, backend=backend, address=address, progress=progress,
                   stats=SweepStats())
