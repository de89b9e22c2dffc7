"""The builder's files: the input CSV formats and the circuit folder it writes.

Inputs: an edges file ``left_x, left_y, right_x, right_y`` (the two edges need
not be paired row by row) or a centreline file ``x_m, y_m, w_tr_right_m,
w_tr_left_m``; both are turned into two closed edges. Output: the circuit
folder read by :meth:`sofar_env.tracks.Track.load` (``raceline.csv``, the two
edge files, ``centerline.csv`` and ``meta.json``; see ``tracks/README.md``).
"""

from __future__ import annotations

import hashlib
import json
import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from ..format import (
    EDGE_COLUMNS,
    LEFT_EDGE_FILE,
    META_FILE,
    RACELINE_COLUMNS,
    RACELINE_FILE,
    RIGHT_EDGE_FILE,
    TrackFormatError,
)
from ..track import Track
from .polyline import clean_closed, tangent_normal

__all__ = [
    "CENTERLINE_FILE",
    "CENTERLINE_COLUMNS",
    "BuiltCircuit",
    "read_edges_csv",
    "read_centerline_csv",
    "sha256",
    "write_circuit",
    "CIRCUIT_FILES",
    "OutputFolderError",
    "CircuitExistsError",
    "check_source",
    "check_output_folder",
]

CENTERLINE_FILE = "centerline.csv"
CENTERLINE_COLUMNS = ("s_m", "x_m", "y_m", "w_left_m", "w_right_m")


@dataclass
class BuiltCircuit:
    """Arrays and metadata of a built circuit (what is written to disk)."""

    raceline: np.ndarray  # (K, 8) columns RACELINE_COLUMNS
    left_edge: np.ndarray
    right_edge: np.ndarray
    centerline: np.ndarray  # (C, 5) columns CENTERLINE_COLUMNS
    meta: dict

    def to_track(self) -> Track:
        return Track(self.meta["name"], self.meta["length_m"], self.raceline, self.left_edge, self.right_edge, self.meta)


# ---------------------------------------------------------------- input files


def sha256(path: Path) -> str:
    """Hex SHA-256 digest of a file (recorded in ``meta.json`` as the input's fingerprint)."""
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 16), b""):
            digest.update(block)
    return digest.hexdigest()


def _reject_other_delimiter(path: Path, lineno: int, line: str, ncols: int) -> None:
    """Raise when a line without commas splits into ``ncols`` fields at ';', a tab or '|'."""
    for sep, shown in ((";", "';'"), ("\t", "tabs"), ("|", "'|'")):
        if line.count(sep) == ncols - 1:
            raise TrackFormatError(
                f"{path}: line {lineno}: expected comma-separated values, found {shown} "
                f"({line[:60]!r}); convert the file to commas (with '.' as the decimal point)"
            )


def check_source(path: str | os.PathLike) -> None:
    """Raise TrackFormatError naming ``path`` unless it is a file this process can read.

    The same messages as the readers give (``file not found``, ``cannot read (...)``), only without
    reading the file: the command line checks its arguments with it before anything runs.
    """
    path = Path(path)
    if not path.exists():
        raise TrackFormatError(f"{path}: file not found")
    if path.is_dir():
        raise TrackFormatError(f"{path}: cannot read (a folder, not a file)")
    try:
        with open(path, "rb"):
            pass
    except OSError as exc:
        raise TrackFormatError(f"{path}: cannot read ({exc})") from None


def _read_numeric_csv(path: Path, ncols: int) -> np.ndarray:
    """Numeric rows of a CSV; '#' comment lines and one non-numeric header line are skipped.

    Raises TrackFormatError naming ``path`` for an unreadable file, a file delimited by
    ';', tabs or '|' instead of commas, a non-numeric value, a wrong number of fields or
    no data rows.
    """
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise TrackFormatError(f"{path}: file not found") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise TrackFormatError(f"{path}: cannot read ({exc})") from None
    rows = []
    for lineno, raw in enumerate(text.splitlines(), start=1):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        if "," not in line:
            _reject_other_delimiter(path, lineno, line, ncols)
        fields = [f.strip() for f in line.split(",")]
        try:
            values = [float(f) if f else math.nan for f in fields]
        except ValueError:
            if not rows:  # a header line
                continue
            raise TrackFormatError(f"{path}: line {lineno}: non-numeric value") from None
        if len(values) != ncols:
            raise TrackFormatError(f"{path}: line {lineno} has {len(values)} fields, expected {ncols}")
        rows.append(values)
    if not rows:
        raise TrackFormatError(f"{path}: no data rows")
    return np.array(rows, dtype=float)


def read_edges_csv(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray]:
    """Edges file ``left_x, left_y, right_x, right_y`` -> (left, right) point arrays.

    Rows need not be paired; an edge may be padded with empty/NaN fields.
    """
    path = Path(path)
    data = _read_numeric_csv(path, 4)
    return clean_closed(data[:, :2], f"{path} (left edge)"), clean_closed(data[:, 2:], f"{path} (right edge)")


def read_centerline_csv(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray]:
    """Centreline file ``x_m, y_m, w_tr_right_m, w_tr_left_m`` -> (left, right) edges."""
    path = Path(path)
    data = _read_numeric_csv(path, 4)
    data = data[np.all(np.isfinite(data), axis=1)]
    center = clean_closed(data[:, :2], str(path))
    # widths of the rows that survived the cleaning (matched by position)
    tree = cKDTree(data[:, :2])
    _, idx = tree.query(center)
    w_right, w_left = data[idx, 2], data[idx, 3]
    if np.any(w_right <= 0) or np.any(w_left <= 0):
        raise TrackFormatError(f"{path}: track widths must be positive")
    _, normal = tangent_normal(center)
    return center + w_left[:, None] * normal, center - w_right[:, None] * normal


# ---------------------------------------------------------------- output folder


CIRCUIT_FILES = (RACELINE_FILE, LEFT_EDGE_FILE, RIGHT_EDGE_FILE, CENTERLINE_FILE, META_FILE)
"""The files :func:`write_circuit` writes (and replaces) in a circuit folder."""


class OutputFolderError(ValueError):
    """The circuit folder cannot be written where asked (see :func:`check_output_folder`)."""


class CircuitExistsError(OutputFolderError):
    """The output folder already holds a circuit, and it is not to be replaced."""


def check_output_folder(folder: str | os.PathLike, *, overwrite: bool = True) -> Path:
    """Check, before a build, that :func:`write_circuit` can write ``folder``; return it as a Path.

    ``folder`` must be an existing folder this process may write into, or not exist yet with its
    nearest existing parent a folder this process may create it in. With ``overwrite=False`` a folder
    that already holds any of :data:`CIRCUIT_FILES` is refused as well (:class:`CircuitExistsError`).
    Raises :class:`OutputFolderError` (a ValueError) saying what is in the way; writes nothing.
    """
    folder = Path(folder)
    if folder.exists() or folder.is_symlink():
        if not folder.is_dir():
            raise OutputFolderError(f"{folder} exists and is not a folder")
        if not os.access(folder, os.W_OK | os.X_OK):
            raise OutputFolderError(f"{folder}: no permission to write into it")
        present = [name for name in CIRCUIT_FILES if (folder / name).exists()]
        if present and not overwrite:
            raise CircuitExistsError(f"{folder} already holds a circuit ({', '.join(present)})")
        return folder
    parent = folder.absolute().parent
    while not parent.exists():
        parent = parent.parent
    if not parent.is_dir():
        raise OutputFolderError(f"{folder}: cannot create it, {parent} is not a folder")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise OutputFolderError(f"{folder}: no permission to create it in {parent}")
    return folder


def write_circuit(folder: str | os.PathLike, built: BuiltCircuit) -> Path:
    """Write the circuit files into ``folder`` (created if needed)."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    fmt_race = ["%.6f", "%.6f", "%.6f", "%.9f", "%.12g", "%.6f", "%.6f", "%.12g"]
    np.savetxt(folder / RACELINE_FILE, built.raceline, delimiter=",", fmt=fmt_race,
               header=",".join(RACELINE_COLUMNS), comments="")
    for edge, fname in ((built.left_edge, LEFT_EDGE_FILE), (built.right_edge, RIGHT_EDGE_FILE)):
        np.savetxt(folder / fname, edge, delimiter=",", fmt="%.6f", header=",".join(EDGE_COLUMNS), comments="")
    np.savetxt(folder / CENTERLINE_FILE, built.centerline, delimiter=",", fmt="%.6f",
               header=",".join(CENTERLINE_COLUMNS), comments="")
    (folder / META_FILE).write_text(json.dumps(built.meta, indent=2) + "\n", encoding="utf-8")
    return folder
