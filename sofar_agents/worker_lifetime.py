"""Worker processes that do not outlive the process that runs them.

A pool worker blocked on its queue, or in the middle of a long episode, does not notice that
its driver was killed (SIGKILL, the OOM killer, a closed terminal): it would finish its work for
nobody and then wait for ever, holding its memory. Called first thing in a worker (as every worker of
:mod:`sofar_agents.worker_processes` does), :func:`exit_with_parent` ends the worker as soon
as its parent ends; :func:`exit_with_process` does the same for a process that is not the
parent (a Ray actor, whose parent is Ray's raylet, tied to the driver on the same machine).

Only the standard library: importing this module costs nothing.
"""

from __future__ import annotations

import ctypes
import logging
import os
import signal
import sys
import threading
import time

__all__ = ["POLL_S", "exit_with_parent", "exit_with_process", "process_alive", "process_start_time"]

logger = logging.getLogger(__name__)

POLL_S = 0.5
"""Seconds between two looks of a watchdog thread at the process it follows."""
_PR_SET_PDEATHSIG = 1  # <linux/prctl.h>


def _set_parent_death_signal() -> bool:
    """Linux: ask the kernel to SIGKILL this process when its parent ends. False where that is unavailable."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        return libc.prctl(_PR_SET_PDEATHSIG, int(signal.SIGKILL), 0, 0, 0) == 0
    except (AttributeError, OSError):
        return False


def _watch(alive, what: str, poll_s: float) -> None:
    """A daemon thread that ends the process with status 1 once ``alive()`` is False."""

    def loop() -> None:
        while alive():
            time.sleep(poll_s)
        logger.debug("%s is gone: this worker exits", what)
        os._exit(1)

    threading.Thread(target=loop, name="sofar-exit-with-" + what.split()[0], daemon=True).start()


def exit_with_parent(parent_pid: int | None = None, *, poll_s: float = POLL_S) -> str:
    """Make this process end when its parent process ends; returns how (``"prctl"`` or ``"watchdog"``).

    ``parent_pid`` is the parent's pid as the parent saw it (``os.getpid()`` there, passed to the
    worker); when given and this process's parent is already another one (the parent died while the
    worker started), the process exits at once with status 1. On Linux the kernel then kills the
    process with SIGKILL when the parent ends (``prctl(PR_SET_PDEATHSIG)``; strictly, when the
    parent's thread that started it ends, so start workers from a thread that outlives them).
    Elsewhere, or where prctl fails, a daemon thread compares ``os.getppid()`` with the parent
    every ``poll_s`` seconds and calls ``os._exit(1)`` once it changed. Never raises.
    """
    parent = os.getppid() if parent_pid is None else int(parent_pid)
    how = "prctl" if _set_parent_death_signal() else "watchdog"
    if os.getppid() != parent:  # the parent ended before the kernel was told
        os._exit(1)
    if how == "watchdog":
        _watch(lambda: os.getppid() == parent, f"parent {parent}", poll_s)
    return how


def process_start_time(pid: int) -> str | None:
    """The start time of process ``pid`` (Linux: clock ticks since boot, from ``/proc``), to tell it
    from a later process that reuses the pid; None where it cannot be read."""
    try:
        with open(f"/proc/{int(pid)}/stat", "rb") as fh:
            stat = fh.read().decode(errors="replace")
    except OSError:
        return None
    fields = stat[stat.rfind(")") + 2:].split()  # after "pid (name) "
    return fields[19] if len(fields) > 19 else None


def process_alive(pid: int, start_time: str | None = None) -> bool:
    """Whether process ``pid`` (on this machine) runs: not ended, not a zombie, and, when
    ``start_time`` (from :func:`process_start_time`) is given, the same process and not a later one
    with its pid."""
    try:
        with open(f"/proc/{int(pid)}/stat", "rb") as fh:
            stat = fh.read().decode(errors="replace")
    except FileNotFoundError:
        return False
    except OSError:  # no /proc: ask the kernel
        try:
            os.kill(int(pid), 0)
        except ProcessLookupError:
            return False
        except PermissionError:
            return True
        return True
    fields = stat[stat.rfind(")") + 2:].split()
    if not fields or fields[0] in ("Z", "X", "x"):  # a zombie has ended; only its exit status is left
        return False
    return start_time is None or (len(fields) > 19 and fields[19] == start_time)


def exit_with_process(pid: int, start_time: str | None = None, *, poll_s: float = POLL_S) -> None:
    """End this process (``os._exit(1)``) once process ``pid`` on this machine has ended.

    For a worker whose parent is not the process it serves (a Ray actor and its driver): a daemon
    thread checks :func:`process_alive` every ``poll_s`` seconds; ``start_time`` (from
    :func:`process_start_time` in the followed process) guards against a reused pid. Exits at once
    when the process is already gone. Never raises.
    """
    if not process_alive(pid, start_time):
        os._exit(1)
    _watch(lambda: process_alive(pid, start_time), f"process {pid}", poll_s)
