"""The permission bits of a file written by replacing it: those of the file it replaces, or those ``open`` gives.

An atomic write creates its temporary file with :func:`tempfile.mkstemp`, which makes it readable by its owner
only (mode 0600), and moves it over the target. Without :func:`publish_mode` every report, CSV and checkpoint so
written would end up 0600 whatever the process's umask, unreadable by the group that shares a results folder.
"""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["publish_mode", "umask"]


def umask() -> int:
    """The process's file mode creation mask (read from ``/proc`` where there is one: setting and restoring it is
    not thread-safe)."""
    try:
        for line in Path("/proc/self/status").read_text(encoding="ascii").splitlines():
            if line.startswith("Umask:"):
                return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def publish_mode(fd: int, target: str | os.PathLike) -> None:
    """Give the open temporary file ``fd`` the permission bits ``target`` has, or, when there is no ``target``
    yet, those of a new file (0666 less the umask). Nothing where the platform has no ``os.fchmod``."""
    if not hasattr(os, "fchmod"):
        return
    try:
        mode = os.stat(target).st_mode & 0o7777
    except FileNotFoundError:
        mode = 0o666 & ~umask()
    os.fchmod(fd, mode)
