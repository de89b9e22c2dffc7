"""The processes below a process, for the tests of worker lifetimes: psutil if installed, else /proc (Linux)."""

from __future__ import annotations

import os
import signal
import time
from collections.abc import Callable
from pathlib import Path

try:
    import psutil
except ImportError:  # the /proc fallback
    psutil = None

Proc = tuple[int, float]
"""A process as (pid, start time): the start time tells it from a later process with the same pid."""


def _proc_stat(pid: int) -> list[str] | None:
    try:
        stat = Path(f"/proc/{pid}/stat").read_bytes().decode(errors="replace")
    except OSError:
        return None
    return stat[stat.rfind(")") + 2:].split()  # state, ppid, ... (fields 3 on)


def _cmdline(pid: int) -> str:
    if psutil is not None:
        try:
            return " ".join(psutil.Process(pid).cmdline())
        except psutil.Error:
            return ""
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace").strip()
    except OSError:
        return ""


def descendants(pid: int) -> dict[Proc, str]:
    """Every process below ``pid`` (children, their children, ...), with its command line."""
    if psutil is not None:
        try:
            kids = psutil.Process(pid).children(recursive=True)
        except psutil.Error:
            return {}
        out = {}
        for k in kids:
            try:
                out[(k.pid, k.create_time())] = " ".join(k.cmdline())
            except psutil.Error:
                continue
        return out
    parent_of, start_of = {}, {}
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            fields = _proc_stat(int(entry.name))
            if fields and len(fields) > 19:
                parent_of[int(entry.name)] = int(fields[1])
                start_of[int(entry.name)] = float(fields[19])
    found, frontier = {}, [pid]
    while frontier:
        p = frontier.pop()
        for child, parent in parent_of.items():
            if parent == p and child not in (q for q, _ in found):
                found[(child, start_of[child])] = _cmdline(child)
                frontier.append(child)
    return found


def alive(proc: Proc) -> bool:
    """Whether the process runs (the same one: same start time; a zombie has ended)."""
    pid, start = proc
    if psutil is not None:
        try:
            p = psutil.Process(pid)
            return p.create_time() == start and p.status() != psutil.STATUS_ZOMBIE
        except psutil.Error:
            return False
    fields = _proc_stat(pid)
    return bool(fields) and len(fields) > 19 and float(fields[19]) == start and fields[0] not in ("Z", "X")


def wait_for(predicate: Callable[[], bool], timeout: float, poll: float = 0.2) -> bool:
    """Poll ``predicate`` until it holds or ``timeout`` seconds passed; its last value."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if predicate():
            return True
        time.sleep(poll)
    return predicate()


def kill_all(procs) -> None:
    """SIGKILL those of ``procs`` that still run (cleanup: never leave a test's processes behind)."""
    for proc in procs:
        if alive(proc):
            try:
                os.kill(proc[0], signal.SIGKILL)
            except OSError:
                pass
