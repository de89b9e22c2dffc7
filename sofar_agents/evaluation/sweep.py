"""Sweeps: run a list of episodes over a process pool (or Ray), appending each result to a CSV.

Workers (spawn context, ``process_pool``) get their episodes one at a time from this process,
build their environments and policies lazily and keep them for later episodes of the same
track/configuration; they end with this process, even when it is killed. Each finished episode
is appended to the CSV (flushed), and episodes already in the CSV are skipped, so an interrupted
sweep resumes where it stopped. With ``backend="ray"`` the episodes run in Ray actors instead
(``ray_backend``); the CSV is written here, by the driver, in the same way. An episode that
failed or was lost with a worker is counted in :class:`SweepStats` (``failed``, ``missing``):
the caller decides whether an incomplete sweep is an error.
"""

from __future__ import annotations

import logging
import math
import os
import time
import traceback
from collections.abc import Sequence
from dataclasses import dataclass, field

from sofar_agents.evaluation.protocol import EpisodeTask
from sofar_agents.evaluation.results import EPISODE_COLUMNS, TRACE_COLUMNS, _AppendingCSV, _row_key, read_episode_csv
from sofar_agents.evaluation.runner import EpisodeRunner as _EpisodeRunner

logger = logging.getLogger(__name__)


@dataclass
class SweepStats:
    """What a sweep did."""

    requested: int = 0
    skipped: int = 0
    """Episodes already in the CSV."""
    completed: int = 0
    failed: int = 0
    """Episodes that raised (logged with their traceback in ``errors``)."""
    missing: int = 0
    """Episodes that got no result because their worker process died (logged)."""
    steps: int = 0
    """Control steps simulated by the completed episodes."""
    episode_wall_time: float = 0.0
    """Sum of the episodes' wall times [s] (about workers x elapsed)."""
    elapsed: float = 0.0
    """Wall time of the sweep [s]."""
    workers: int = 0
    errors: list[str] = field(default_factory=list)

    @property
    def unfinished(self) -> int:
        """Episodes of this run left out of the CSV (``failed + missing``): a rerun retries them."""
        return self.failed + self.missing

    @property
    def steps_per_second_per_worker(self) -> float:
        return self.steps / self.episode_wall_time if self.episode_wall_time > 0 else math.nan

    def estimate_hours(self, total_steps: float, workers: int) -> float:
        """Wall hours for ``total_steps`` control steps on ``workers`` workers at the measured speed."""
        rate = self.steps_per_second_per_worker
        return total_steps / (rate * max(workers, 1)) / 3600.0 if rate > 0 else math.nan


def _progress_bar(total: int, enabled: bool):
    from tqdm.auto import tqdm

    return tqdm(total=total, unit="ep", desc="episodes", disable=not enabled, dynamic_ncols=True, smoothing=0.05)


def run_sweep(tasks: Sequence[EpisodeTask], csv_path: str | os.PathLike, *, workers: int | None = None,
              trace_path: str | os.PathLike | None = None, progress: bool = True, backend: str = "local",
              address: str | None = None) -> SweepStats:
    """Run every task not yet in ``csv_path``, appending one row per finished episode.

    ``backend="local"``: ``workers`` processes (None: ``os.cpu_count()``; 1 runs in this
    process; below 1 raises ValueError). ``backend="ray"``: ``workers`` Ray actors (default: the CPUs of the Ray instance)
    on a local Ray instance, or on the cluster at ``address`` (``"auto"`` or ``"HOST:6379"``);
    see :mod:`~sofar_agents.evaluation.ray_backend`. Either way only this process writes the
    CSV, and no worker outlives it. A failed episode (``stats.failed``) or one lost with a worker
    process that died (``stats.missing``) is logged and left out of the CSV, so the next run
    retries it; check ``stats.unfinished`` to treat an incomplete sweep as an error.
    """
    if backend not in ("local", "ray"):
        raise ValueError(f"unknown sweep backend {backend!r} (expected 'local' or 'ray')")
    if address is not None and backend != "ray":
        raise ValueError("address (a Ray cluster) needs backend='ray'")
    if workers is not None and int(workers) < 1:  # 0 is not "unset": None is
        raise ValueError(f"workers must be >= 1 (or None: one per CPU), got {workers!r}")
    if backend == "ray":
        from sofar_agents.evaluation import ray_backend

        ray_backend.require_ray(local=address is None)  # fail before reading anything if Ray is missing
    t_start = time.perf_counter()
    done = {_row_key(r) for r in read_episode_csv(csv_path)}
    pending, seen = [], set()
    for t in tasks:
        if t.key not in done and t.key not in seen:
            pending.append(t)
            seen.add(t.key)
    stats = SweepStats(requested=len(tasks), skipped=len(tasks) - len(pending))
    if not pending:
        stats.elapsed = time.perf_counter() - t_start
        return stats
    pending.sort(key=lambda t: (t.env_key, t.strategy.name))
    n_workers = max(1, min(int(workers or os.cpu_count() or 1), len(pending)))
    stats.workers = n_workers  # the Ray backend replaces it with its number of actors
    out = _AppendingCSV(csv_path, EPISODE_COLUMNS)
    trace_out = _AppendingCSV(trace_path, TRACE_COLUMNS) if trace_path is not None else None
    from sofar_env.compile import warm_up

    warm_up(sorted({t.scenario for t in pending}), multi_agent=False)  # compile here, not inside the bar's ETA
    bar = _progress_bar(len(pending), progress)

    def handle(msg) -> None:
        status, idx, payload, trace = msg
        if status == "ok":
            out.write(payload)
            if trace_out is not None and trace:
                trace_out.write_many(trace)
            stats.completed += 1
            stats.steps += int(payload["steps"])
            stats.episode_wall_time += float(payload["wall_time"])
            rate = stats.steps / stats.episode_wall_time if stats.episode_wall_time > 0 else 0.0
            bar.set_postfix(steps_per_s=f"{rate * max(stats.workers, 1):.0f}", failed=stats.failed, refresh=False)
        else:
            stats.failed += 1
            stats.errors.append(payload)
            t = pending[idx]
            logger.error("episode %s/%s rho=%g seed=%d failed:\n%s", t.track, t.strategy.name, t.rho, t.seed, payload)
        bar.update(1)

    try:
        if backend == "ray":
            stats.workers = ray_backend.run_ray(pending, handle, workers=workers, address=address)
        elif n_workers == 1:
            runner = _EpisodeRunner()
            try:
                for i, t in enumerate(pending):
                    try:
                        res, trace = runner.run(t)
                        handle(("ok", i, res.to_row(), trace))
                    except Exception:
                        handle(("error", i, traceback.format_exc(), None))
            finally:
                runner.close()
        else:
            from sofar_agents.evaluation.process_pool import run_pool

            stats.missing = run_pool(pending, n_workers, handle, _EpisodeRunner)
    finally:
        bar.close()
        out.close()
        if trace_out is not None:
            trace_out.close()
        stats.elapsed = time.perf_counter() - t_start
    return stats


def incomplete_message(stats: SweepStats, out: str | os.PathLike, unit: str = "episodes") -> str | None:
    """What a script reports for a sweep that left episodes out of its CSV, or None if it did not.

    Says how many are missing, why (failed, or lost with a worker process that died), and that
    re-running the same command with the same ``out`` folder resumes: the CSV keeps the finished
    episodes and only the missing ones run. Scripts log it as an error and exit with status 1.
    """
    if not stats.unfinished:
        return None
    why = []
    if stats.failed:
        why.append(f"{stats.failed} failed")
    if stats.missing:
        why.append(f"{stats.missing} lost with a worker process that died")
    return (f"incomplete: {stats.unfinished} of {stats.requested} {unit} are missing ({', '.join(why)}); re-run "
            f"with the same --out {out} to resume (the finished {unit} are kept, only the missing ones run)")
