"""The local backend of the sweeps: episodes in worker processes of this machine, one pipe each.

The driver starts ``n_workers`` processes (spawn context) and keeps one episode in flight per
worker: it sends a task down the worker's pipe and, when the result comes back, the next one, in
the order of ``pending`` (sorted by track and configuration, so a worker mostly meets the
environment it has built). Results go to the caller's ``handle`` in the driver, which alone writes
the CSV. There is no Manager and no shared queue, so nothing but the workers can outlive the
driver, and a worker that dies loses the one episode it was running, not the rest of the sweep:
the others go on with the remaining episodes, and the lost one is counted (a rerun retries it).

Lifetime: a worker calls :func:`~sofar_agents.worker_lifetime.exit_with_parent` first, so a driver
killed with SIGKILL takes its workers along (Linux: at once, by the kernel; elsewhere within
:data:`~sofar_agents.worker_lifetime.POLL_S`); an idle worker also ends on the end of its pipe. A
worker ignores SIGINT: Ctrl-C is the driver's, which then stops the workers.
"""

from __future__ import annotations

import logging
import multiprocessing as mp
import os
import signal
import traceback
import warnings
from collections.abc import Callable, Sequence
from multiprocessing.connection import Connection, wait

from sofar_agents.evaluation.protocol import EpisodeTask
from sofar_agents.worker_lifetime import exit_with_parent

__all__ = ["run_pool"]

logger = logging.getLogger(__name__)

STOP_TIMEOUT_S = 10.0
"""How long a worker may take to close its environments after the last episode before it is killed [s]."""


def _worker_main(conn: Connection, runner_cls: type, parent_pid: int) -> None:
    """Worker process: run the ``(index, task)`` items sent on ``conn`` until ``None`` or the pipe's end.

    Answers each with ``(status, index, row or traceback, trace)``: ``("ok", i, row, trace)`` or
    ``("error", i, traceback, None)`` for an episode that raised.
    """
    exit_with_parent(parent_pid)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    warnings.simplefilter("ignore", UserWarning)  # the driver reports failures; keep worker output quiet
    runner = runner_cls()
    try:
        while True:
            try:
                item = conn.recv()
            except (EOFError, OSError):  # the driver is gone
                break
            if item is None:
                break
            idx, task = item
            try:
                result, trace = runner.run(task)
                msg = ("ok", idx, result.to_row(), trace)
            except Exception:
                msg = ("error", idx, traceback.format_exc(), None)
            try:
                conn.send(msg)
            except OSError:
                break
    finally:
        runner.close()
        conn.close()


def _receive(conn: Connection):
    """The worker's answer waiting on ``conn``, or None if the worker is gone without one."""
    try:
        return conn.recv() if conn.poll() else None
    except (EOFError, OSError):
        return None


def run_pool(pending: Sequence[EpisodeTask], n_workers: int, handle: Callable, runner_cls: type) -> int:
    """Run ``pending`` on ``n_workers`` worker processes, calling ``handle(msg)`` here for every episode.

    ``msg`` is ``(status, index into pending, row or traceback, trace)``; each worker holds one
    ``runner_cls()`` (``run(task) -> (EpisodeResult, trace)``, ``close()``). Returns the number of
    episodes that got no result because their worker process died (each logged as an error; the
    episodes of a worker that died wait for the others, and if every worker died, the episodes never
    started are counted too). On any exception here (Ctrl-C included) the workers are killed before
    it propagates; otherwise they are stopped once the episodes are done.
    """
    ctx = mp.get_context("spawn")
    procs: list = []
    conns: list[Connection] = []
    in_flight: dict[int, int] = {}  # worker -> index into pending
    next_idx = 0
    lost = 0

    def dispatch(w: int) -> None:
        nonlocal next_idx
        if next_idx < len(pending):
            try:
                conns[w].send((next_idx, pending[next_idx]))
            except OSError:  # the worker is gone; nothing was handed to it
                return
            in_flight[w] = next_idx
            next_idx += 1

    try:
        for w in range(n_workers):
            parent_end, child_end = ctx.Pipe()
            proc = ctx.Process(target=_worker_main, args=(child_end, runner_cls, os.getpid()),
                               name=f"sofar-sweep-{w}", daemon=True)
            proc.start()
            child_end.close()
            procs.append(proc)
            conns.append(parent_end)
            dispatch(w)
        while in_flight:
            handles = {conns[w]: w for w in in_flight} | {procs[w].sentinel: w for w in in_flight}
            seen: set[int] = set()
            for ready in wait(list(handles)):
                w = handles[ready]
                if w in seen or w not in in_flight:
                    continue
                seen.add(w)
                msg = _receive(conns[w])
                idx = in_flight.pop(w)
                if msg is None:
                    lost += 1
                    procs[w].join(1.0)
                    t = pending[idx]
                    logger.error("worker process %s died (exit code %s) running episode %s/%s rho=%g seed=%d: "
                                 "it is left out of the CSV, a rerun retries it", procs[w].name, procs[w].exitcode,
                                 t.track, t.strategy.name, t.rho, t.seed)
                    continue
                handle(msg)
                dispatch(w)
        if next_idx < len(pending):
            lost += len(pending) - next_idx
            logger.error("every worker process died: %d episodes were not started", len(pending) - next_idx)
    except BaseException:
        for proc in procs:
            proc.kill()
        for proc in procs:
            proc.join(1.0)
        raise
    for conn in conns:
        try:
            conn.send(None)
        except OSError:
            pass
    for proc in procs:
        proc.join(STOP_TIMEOUT_S)
        if proc.is_alive():
            proc.kill()
            proc.join(1.0)
    for conn in conns:
        conn.close()
    return lost
