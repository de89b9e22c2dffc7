"""Worker processes of this machine, one pipe each: the transport of every process pool of the package.

The executor's process backend (:mod:`sofar_agents.executor.processes`: the tables and the replays) and the
training process pool (:class:`~sofar_agents.pasta.process_rollout.ProcessEnvPool`) start their workers here, so
they start, talk and end the same way:

* **Start**: the ``spawn`` method (no state inherited from the driver, whose torch threads a forked child must
  not share; the main script must therefore be importable, so not ``python -`` reading standard input). The
  worker builds its *body* with ``body_factory()`` (a picklable zero-argument callable) and serves calls of its
  methods; ``cpu`` pins it to one CPU.
* **Calls**: :meth:`WorkerProcess.call` sends ``(method, args)``; the worker answers ``(True, value)``, or
  ``(False, text)`` when the method raised (the exception on the first line, then the worker's traceback).
  :meth:`WorkerProcess.answer` returns the value or raises :class:`WorkerFailed` with that text. With
  ``announce=True`` the construction is answered too (``(True, None)`` or ``(False, text)``) before any call;
  without it, a body that fails to build answers ``(False, text)`` to the first call and the worker ends.
* **Lifetime**: the worker calls :func:`~sofar_agents.worker_lifetime.exit_with_parent` first, so a driver killed
  with SIGKILL takes it along; it ignores SIGINT (Ctrl-C is the driver's, which then stops or kills it); an idle
  worker ends on ``None`` or on the end of its pipe, after ``body.close()`` (when the body has one). A worker
  that is gone makes :meth:`~WorkerProcess.call` and :meth:`~WorkerProcess.answer` raise :class:`WorkerGone`.

Only the standard library and :mod:`~sofar_agents.worker_lifetime`: importing this module costs nothing.
"""

from __future__ import annotations

import logging
import multiprocessing as mp
import os
import signal
import traceback
from collections.abc import Callable, Iterable
from multiprocessing.connection import Connection, wait
from typing import Any

from sofar_agents.worker_lifetime import exit_with_parent

__all__ = ["STOP_TIMEOUT_S", "WorkerFailed", "WorkerGone", "WorkerProcess", "kill_workers", "stop_workers",
           "wait_ready"]

logger = logging.getLogger(__name__)

STOP_TIMEOUT_S = 10.0
"""How long a worker may take to close its body after ``None`` before it is killed [s]."""


class WorkerGone(RuntimeError):
    """The worker process ended (or its pipe broke) before it answered."""


class WorkerFailed(RuntimeError):
    """The called method raised in the worker; the message is its exception and traceback."""


def describe_failure(exc: BaseException) -> str:
    """The exception on its first line, then the traceback of the exception being handled (in the worker)."""
    return "".join(traceback.format_exception_only(exc)).strip() + "\n\nin the worker:\n" + traceback.format_exc()


def _serve(conn: Connection, body_factory: Callable[[], Any], parent_pid: int, cpu: int | None,
           announce: bool) -> None:
    """Worker process: build the body, then answer ``(method, args)`` calls until ``None`` or the pipe's end."""
    exit_with_parent(parent_pid)
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the driver's to handle: it then stops the workers
    if cpu is not None:
        os.sched_setaffinity(0, {cpu})
    try:
        body = body_factory()
    except Exception as exc:  # noqa: BLE001 (any failure is reported to the driver)
        try:
            if not announce:
                conn.recv()  # answered as the first call's answer
            conn.send((False, describe_failure(exc)))
        except (EOFError, OSError):
            pass
        conn.close()
        return
    try:
        if announce:
            conn.send((True, None))
        while True:
            try:
                msg = conn.recv()
            except (EOFError, OSError):  # the driver is gone
                break
            if msg is None:
                break
            method, args = msg
            try:
                answer = (True, getattr(body, method)(*args))
            except Exception as exc:  # noqa: BLE001 (any failure is reported to the driver)
                answer = (False, describe_failure(exc))
            try:
                conn.send(answer)
            except OSError:
                break
    except OSError:
        pass
    finally:
        close = getattr(body, "close", None)
        if close is not None:
            close()
        conn.close()


class WorkerProcess:
    """One worker process serving the body ``body_factory()`` over a pipe (see the module docstring).

    Started on construction. Not thread-safe: one driver thread calls and reads its answers, one call at a time
    unless the caller keeps count of the answers it is owed.
    """

    def __init__(self, body_factory: Callable[[], Any], *, name: str, cpu: int | None = None,
                 announce: bool = False) -> None:
        ctx = mp.get_context("spawn")
        self.conn, child = ctx.Pipe()
        self.process = ctx.Process(target=_serve, args=(child, body_factory, os.getpid(), cpu, announce),
                                   name=name, daemon=True)
        self.process.start()
        child.close()

    @property
    def name(self) -> str:
        return self.process.name

    @property
    def sentinel(self) -> int:
        """Ready (for :func:`multiprocessing.connection.wait`) once the process has ended."""
        return self.process.sentinel

    @property
    def exitcode(self) -> int | None:
        return self.process.exitcode

    def gone(self) -> WorkerGone:
        """The error for a worker that ended: names its exit code."""
        self.process.join(1.0)
        return WorkerGone(f"the process exited (exit code {self.process.exitcode})")

    def call(self, method: str, *args: Any) -> None:
        """Send a call of the body's ``method``; :class:`WorkerGone` if the pipe is broken."""
        try:
            self.conn.send((method, args))
        except (OSError, ValueError) as err:  # a broken or closed pipe: the worker is gone
            raise self.gone() from err

    def answer(self) -> Any:
        """The next answer (blocking): the value, or :class:`WorkerFailed` / :class:`WorkerGone`."""
        try:
            ok, value = self.conn.recv()
        except (EOFError, OSError) as err:
            raise self.gone() from err
        if not ok:
            raise WorkerFailed(value)
        return value

    def kill(self) -> None:
        """SIGKILL the worker and reap it (its pipe stays open for :func:`stop_workers`)."""
        self.process.kill()
        self.process.join(1.0)


def wait_ready(workers: Iterable[WorkerProcess]) -> list[WorkerProcess]:
    """Block until at least one of ``workers`` has an answer waiting or has ended; those workers."""
    handles: dict[Any, WorkerProcess] = {}
    for w in workers:
        handles[w.conn] = w
        handles[w.sentinel] = w
    ready = wait(list(handles))
    return list(dict.fromkeys(handles[h] for h in ready))


def stop_workers(workers: Iterable[WorkerProcess], timeout: float = STOP_TIMEOUT_S) -> None:
    """Ask every worker to stop (``None``), wait up to ``timeout`` seconds for each, kill the rest; close the
    pipes. Never raises for a worker that is already gone."""
    workers = list(workers)
    for w in workers:
        try:
            w.conn.send(None)
        except (OSError, ValueError):  # the worker is gone
            pass
    for w in workers:
        w.process.join(timeout)
        if w.process.is_alive():
            logger.warning("worker process %s did not stop within %g s: killed", w.name, timeout)
            w.kill()
    for w in workers:
        w.conn.close()


def kill_workers(workers: Iterable[WorkerProcess]) -> None:
    """SIGKILL every worker at once (on an error or Ctrl-C in the driver) and close the pipes."""
    workers = list(workers)
    for w in workers:
        w.process.kill()
    for w in workers:
        w.process.join(1.0)
        w.conn.close()
