"""Atomic writes of result files: a report, a JSON record or a rewritten CSV is either the old file or the new one.

Every writer here writes the whole content to a temporary file in the target's folder, flushes it to disk and
moves it over the target with ``os.replace`` (atomic on POSIX and Windows within one file system). A write that
fails (a full disk, Ctrl-C, a value that cannot be serialised) leaves the target as it was and no temporary file
behind; the error propagates. The target's folder is created when missing. The new file has the permission bits
of the one it replaces, or those of a new file (:mod:`sofar_agents.file_modes`).
"""

from __future__ import annotations

import hashlib
import json
import os
import tempfile
from pathlib import Path
from typing import Any

from sofar_agents.file_modes import publish_mode

__all__ = ["content_id", "write_bytes_atomic", "write_text_atomic", "write_json_atomic"]


def write_bytes_atomic(path: str | os.PathLike, data: bytes) -> Path:
    """Replace ``path`` by ``data`` atomically (module docstring); returns the path."""
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=p.parent, prefix=f".{p.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as f:
            publish_mode(f.fileno(), p)
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, p)
    finally:
        Path(tmp).unlink(missing_ok=True)
    return p


def write_text_atomic(path: str | os.PathLike, text: str, encoding: str = "utf-8") -> Path:
    """Replace ``path`` by ``text`` (encoded with ``encoding``, newlines written as given) atomically."""
    return write_bytes_atomic(path, text.encode(encoding))


def write_json_atomic(path: str | os.PathLike, data: Any, *, trailing_newline: bool = True, **dump: Any) -> Path:
    """Replace ``path`` by ``json.dumps(data, **dump)`` (and a newline) atomically. The text is made before
    anything is written, so data that cannot be serialised leave the file as it was."""
    text = json.dumps(data, **dump) + ("\n" if trailing_newline else "")
    return write_text_atomic(path, text)


def content_id(*paths: str | os.PathLike) -> str:
    """First 10 hex digits of the SHA-1 of the files' contents, in order (a policy's id in result rows)."""
    h = hashlib.sha1()
    for path in paths:
        with open(path, "rb") as f:
            for chunk in iter(lambda: f.read(1 << 20), b""):
                h.update(chunk)
    return h.hexdigest()[:10]
