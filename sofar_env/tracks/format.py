"""The on-disk circuit format: file names, columns, parsing and consistency checks.

A circuit folder holds four files (see ``tracks/README.md`` for the details)::

    raceline.csv     s_m, x_m, y_m, psi_rad, kappa_radpm, w_left_m, w_right_m, v_mps
    left_edge.csv    x_m, y_m   (closed polyline, first point not repeated)
    right_edge.csv   x_m, y_m
    meta.json        {"format_version": 1, "name": ..., "length_m": ..., ...}

Every error is a :class:`TrackFormatError` whose message starts with the file it is about.
"""

from __future__ import annotations

import json
import math
import os
from typing import Any, Sequence

import numpy as np

__all__ = [
    "FORMAT_VERSION",
    "RACELINE_FILE",
    "LEFT_EDGE_FILE",
    "RIGHT_EDGE_FILE",
    "META_FILE",
    "RACELINE_COLUMNS",
    "EDGE_COLUMNS",
    "LENGTH_TOLERANCE",
    "TrackFormatError",
    "parse_csv_table",
    "read_text",
    "describe",
    "parse_meta",
    "check_raceline_samples",
]

FORMAT_VERSION = 1
"""Version of the on-disk circuit format written by the builder."""

RACELINE_FILE = "raceline.csv"
LEFT_EDGE_FILE = "left_edge.csv"
RIGHT_EDGE_FILE = "right_edge.csv"
META_FILE = "meta.json"

RACELINE_COLUMNS = ("s_m", "x_m", "y_m", "psi_rad", "kappa_radpm", "w_left_m", "w_right_m", "v_mps")
EDGE_COLUMNS = ("x_m", "y_m")

LENGTH_TOLERANCE = 0.01
"""Largest relative difference accepted between ``length_m`` and the closed length of the
raceline samples [-] (the samples are about 1 m apart, so the chords are shorter than the
spline by far less than this)."""


class TrackFormatError(ValueError):
    """A circuit file is missing or malformed; the message names the file."""


def parse_csv_table(text: str, filename: str, columns: Sequence[str], min_rows: int) -> np.ndarray:
    """Parse a comma-separated table with one header line naming ``columns``.

    Returns a float array of shape (rows, len(columns)).  Raises TrackFormatError
    naming ``filename`` on a wrong header, a wrong number of fields, a
    non-numeric or non-finite value, or fewer than ``min_rows`` rows.
    """
    lines = [ln.strip() for ln in text.splitlines()]
    lines = [ln for ln in lines if ln]
    if not lines:
        raise TrackFormatError(f"{filename}: file is empty")
    header = [h.strip() for h in lines[0].lstrip("#").split(",")]
    if tuple(header) != tuple(columns):
        raise TrackFormatError(
            f"{filename}: wrong columns {header}; expected header line {','.join(columns)}"
        )
    data = lines[1:]
    ncol = len(columns)
    if len(data) < min_rows:
        raise TrackFormatError(f"{filename}: {len(data)} data rows, at least {min_rows} required")
    counts = {ln.count(",") for ln in data}
    if counts != {ncol - 1}:
        for k, ln in enumerate(data):
            if ln.count(",") != ncol - 1:
                raise TrackFormatError(
                    f"{filename}: line {k + 2} has {ln.count(',') + 1} fields, expected {ncol}"
                )
    try:
        values = np.array(",".join(data).split(","), dtype=float)
    except ValueError:
        for k, ln in enumerate(data):
            for field in ln.split(","):
                try:
                    float(field)
                except ValueError:
                    raise TrackFormatError(
                        f"{filename}: line {k + 2}: non-numeric value {field.strip()!r}"
                    ) from None
        raise TrackFormatError(f"{filename}: non-numeric value") from None
    values = values.reshape(len(data), ncol)
    bad = ~np.isfinite(values)
    if bad.any():
        row, col = np.argwhere(bad)[0]
        raise TrackFormatError(
            f"{filename}: line {row + 2}: non-finite value in column {columns[col]}"
        )
    return values


def read_text(folder: Any, filename: str) -> str:
    """Read ``folder/filename`` (a Path or an importlib Traversable)."""
    entry = folder / filename
    try:
        return entry.read_text(encoding="utf-8")
    except (FileNotFoundError, IsADirectoryError, NotADirectoryError):
        raise TrackFormatError(f"{describe(folder, filename)}: file not found") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise TrackFormatError(f"{describe(folder, filename)}: cannot read ({exc})") from None


def describe(folder: Any, filename: str) -> str:
    """The path of ``folder/filename`` as shown in error messages."""
    return os.fspath(folder / filename) if isinstance(folder, os.PathLike) else str(folder / filename)


def parse_meta(text: str, where: str) -> dict:
    """The ``meta.json`` object; checks the format version, ``length_m`` and ``name``."""
    try:
        meta = json.loads(text)
    except json.JSONDecodeError as exc:
        raise TrackFormatError(f"{where}: invalid JSON ({exc})") from None
    if not isinstance(meta, dict):
        raise TrackFormatError(f"{where}: expected a JSON object")
    version = meta.get("format_version")
    if version != FORMAT_VERSION:
        raise TrackFormatError(
            f"{where}: unsupported format_version {version!r}, expected {FORMAT_VERSION}"
        )
    length = meta.get("length_m")
    if not isinstance(length, (int, float)) or not math.isfinite(length) or length <= 0:
        raise TrackFormatError(f"{where}: length_m must be a positive number, got {length!r}")
    if not isinstance(meta.get("name"), str):
        raise TrackFormatError(f"{where}: missing string field 'name'")
    return meta


def check_raceline_samples(raceline: np.ndarray, length: float, where: str, meta_where: str) -> None:
    """Check that the raceline columns agree with each other and with ``length_m``.

    ``raceline`` holds the columns :data:`RACELINE_COLUMNS` (as parsed from ``where``) and
    ``length`` the lap length read from ``meta_where``. Raises TrackFormatError when the
    closed length of the sampled positions differs from ``length`` by more than
    :data:`LENGTH_TOLERANCE`, when a width is not positive, or when a speed is not
    positive (the parser has already rejected non-finite values).
    """
    xy = raceline[:, 1:3]
    closed = np.vstack([xy, xy[:1]])
    sampled = float(np.sum(np.hypot(*np.diff(closed, axis=0).T)))
    if not abs(sampled - length) <= LENGTH_TOLERANCE * length:
        raise TrackFormatError(
            f"{meta_where}: length_m {length:g} m contradicts the raceline samples of {where}, "
            f"whose closed length is {sampled:.1f} m (tolerance {100 * LENGTH_TOLERANCE:g} %)"
        )
    for col, what in ((5, "width w_left_m"), (6, "width w_right_m"), (7, "speed v_mps")):
        bad = ~(raceline[:, col] > 0.0)
        if bad.any():
            row = int(np.argmax(bad))
            raise TrackFormatError(
                f"{where}: line {row + 2}: {what} must be positive, got {raceline[row, col]:g}"
                f" ({int(bad.sum())} of {len(raceline)} rows are not)"
            )
