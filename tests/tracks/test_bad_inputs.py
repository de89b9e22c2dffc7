"""Bad input gets a clear error naming the file and the problem, and no traceback.

One table for the builder (``python -m sofar_env.tracks build`` run as a subprocess with
a timeout, so that a hang fails the test instead of stalling it; the input checks are
:mod:`sofar_env.tracks.builder.checks`) and one for :meth:`Track.load` on a copy of a
shipped circuit with one thing broken (the consistency checks of
:mod:`sofar_env.tracks.format`). Each row is (how to make the input, words the error
message must contain). The malformed-file tests of the format parser follow.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
from importlib import resources
from pathlib import Path

import numpy as np
import pytest
from shipped_circuits import copy_circuit
from synthetic_circuits import write_edges

from sofar_env.tracks import Track, TrackFormatError

SOURCE = "Kentucky"  # the smallest shipped circuit
BUILD_TIMEOUT = 60.0  # [s] far above the few seconds a rejected input takes; a hang fails


def _source_rows() -> list[str]:
    """Rows of an edges file: the shipped Kentucky edges, as written to its circuit folder."""
    folder = resources.files("sofar_env.track_data").joinpath(SOURCE)
    left = np.loadtxt(str(folder.joinpath("left_edge.csv")), delimiter=",", skiprows=1)
    right = np.loadtxt(str(folder.joinpath("right_edge.csv")), delimiter=",", skiprows=1)
    rows = min(len(left), len(right))
    return [f"{a:.6f},{b:.6f},{c:.6f},{d:.6f}" for (a, b), (c, d) in zip(left[:rows], right[:rows])]


def _edges(path: Path, left: np.ndarray, right: np.ndarray) -> Path:
    write_edges(path, left, right)
    return path


def figure_eight(path: Path) -> Path:
    """Edges 5 m either side of a figure-eight centre line (crossing itself at the origin)."""
    t = np.linspace(0.0, 2.0 * math.pi, 800, endpoint=False)
    center = np.column_stack([200.0 * np.sin(t), 100.0 * np.sin(2.0 * t)])
    tangent = np.column_stack([200.0 * np.cos(t), 200.0 * np.cos(2.0 * t)])
    normal = np.column_stack([-tangent[:, 1], tangent[:, 0]]) / np.hypot(*tangent.T)[:, None]
    return _edges(path, center + 5.0 * normal, center - 5.0 * normal)


def zero_width(path: Path) -> Path:
    """The left edge given as both edges."""
    rows = [r.split(",") for r in _source_rows()]
    path.write_text("\n".join(f"{a},{b},{a},{b}" for a, b, _, _ in rows) + "\n")
    return path


def edges_cross(path: Path) -> Path:
    """Two circles of the same radius whose centres are 20 m apart: the edges cross twice."""
    t = np.linspace(0.0, 2.0 * math.pi, 300, endpoint=False)
    ring = np.column_stack([60.0 * np.cos(t), 60.0 * np.sin(t)])
    return _edges(path, ring, ring + np.array([20.0, 0.0]))


def open_strip(path: Path) -> Path:
    """The first 60 % of the rows of a real circuit: an edge that stops half-way round."""
    rows = _source_rows()
    path.write_text("\n".join(rows[: int(0.6 * len(rows))]) + "\n")
    return path


def delimited(sep: str):
    def make(path: Path) -> Path:
        path.write_text("\n".join(r.replace(",", sep) for r in _source_rows()) + "\n")
        return path

    return make


BUILD_CASES = {
    # case: (make input, words the message must contain)
    "figure-eight": (figure_eight, ["crosses itself", "left edge"]),
    "zero-width": (zero_width, ["zero track width", "coincide"]),
    "edges-cross": (edges_cross, ["left and right edges cross"]),
    "open-strip": (open_strip, ["not closed", "left edge"]),
    "semicolons": (delimited(";"), ["expected comma-separated values", "';'", "line 1"]),
    "tabs": (delimited("\t"), ["expected comma-separated values", "tabs"]),
}


@pytest.mark.parametrize("case", sorted(BUILD_CASES))
def test_builder_rejects_bad_input_at_once(tmp_path, case):
    make, words = BUILD_CASES[case]
    source = make(tmp_path / f"{case}.csv")
    out = tmp_path / "out"
    proc = subprocess.run(
        [sys.executable, "-m", "sofar_env.tracks", "build", str(source), "--name", "Bad", "--out", str(out)],
        capture_output=True,
        text=True,
        timeout=BUILD_TIMEOUT,
    )
    assert proc.returncode == 2, proc.stderr
    assert "Traceback" not in proc.stderr
    assert proc.stderr.startswith("error: ")
    assert str(source) in proc.stderr
    for word in words:
        assert word in proc.stderr
    assert not out.exists()


def test_checks_pass_the_shipped_edges():
    """The input checks accept a real circuit (the files are its stored, closed edges)."""
    from sofar_env.tracks.builder.checks import check_edges

    folder = resources.files("sofar_env.track_data").joinpath(SOURCE)
    left = np.loadtxt(str(folder.joinpath("left_edge.csv")), delimiter=",", skiprows=1)
    right = np.loadtxt(str(folder.joinpath("right_edge.csv")), delimiter=",", skiprows=1)
    check_edges(left, right, SOURCE)


# ------------------------------------------------------------------ Track.load


def set_meta(key, value):
    def edit(folder: Path) -> None:
        meta = json.loads((folder / "meta.json").read_text())
        meta[key] = value
        (folder / "meta.json").write_text(json.dumps(meta))

    return edit


def set_column(fname: str, column: str, value: float, rows: slice):
    def edit(folder: Path) -> None:
        path = folder / fname
        lines = path.read_text().splitlines()
        col = lines[0].split(",").index(column)
        body = [ln.split(",") for ln in lines[1:]]
        for fields in body[rows]:
            fields[col] = repr(value)
        path.write_text("\n".join([lines[0]] + [",".join(f) for f in body]) + "\n")

    return edit


ALL, ONE = slice(None), slice(100, 101)

LOAD_CASES = {
    # case: (break the copy, the file the message names, words it must contain)
    "length-too-long": (set_meta("length_m", 10000.0), "meta.json", ["length_m", "contradicts", "raceline.csv"]),
    "length-2pc-long": (set_meta("length_m", 2415.0), "meta.json", ["length_m", "contradicts"]),
    "negative-width": (set_column("raceline.csv", "w_left_m", -1.0, ONE), "raceline.csv", ["line 102", "w_left_m", "positive"]),
    "zero-width": (set_column("raceline.csv", "w_right_m", 0.0, ALL), "raceline.csv", ["w_right_m", "positive"]),
    "speed-all-zero": (set_column("raceline.csv", "v_mps", 0.0, ALL), "raceline.csv", ["v_mps", "positive"]),
    "speed-negative": (set_column("raceline.csv", "v_mps", -5.0, ONE), "raceline.csv", ["line 102", "v_mps", "positive"]),
    "speed-nan": (set_column("raceline.csv", "v_mps", math.nan, ONE), "raceline.csv", ["line 102", "non-finite", "v_mps"]),
    "x-inf": (set_column("raceline.csv", "x_m", math.inf, ONE), "raceline.csv", ["line 102", "non-finite", "x_m"]),
    "edge-nan": (set_column("left_edge.csv", "y_m", math.nan, ONE), "left_edge.csv", ["line 102", "non-finite", "y_m"]),
}


@pytest.mark.parametrize("case", sorted(LOAD_CASES))
def test_load_rejects_inconsistent_circuit(tmp_path, case):
    edit, fname, words = LOAD_CASES[case]
    folder = copy_circuit(SOURCE, tmp_path)
    edit(folder)
    with pytest.raises(TrackFormatError) as info:
        Track.load(folder)
    message = str(info.value)
    assert message.startswith(str(folder / fname))
    for word in words:
        assert word in message


def test_info_reports_a_broken_folder_without_traceback(tmp_path):
    folder = copy_circuit(SOURCE, tmp_path)
    set_meta("length_m", 10000.0)(folder)
    proc = subprocess.run(
        [sys.executable, "-m", "sofar_env.tracks", "info", str(folder)],
        capture_output=True, text=True, timeout=BUILD_TIMEOUT,
    )
    assert proc.returncode == 2
    assert proc.stderr.startswith(f"error: {folder / 'meta.json'}: length_m")
    assert "Traceback" not in proc.stderr


def test_load_accepts_the_shipped_circuit_after_a_round_trip(tmp_path):
    """The copy itself is consistent: the cases above fail because of their one change."""
    assert Track.load(copy_circuit(SOURCE, tmp_path)).name == SOURCE


# ------------------------------------------- malformed files (parser of sofar_env.tracks.format)


@pytest.mark.parametrize("fname", ["raceline.csv", "left_edge.csv", "right_edge.csv", "meta.json"])
def test_missing_file_names_the_file(tmp_path, fname):
    folder = copy_circuit(SOURCE, tmp_path)
    (folder / fname).unlink()
    with pytest.raises(TrackFormatError, match=fname):
        Track.load(folder)


def _edit_lines(path, edit):
    lines = path.read_text().splitlines()
    path.write_text("\n".join(edit(lines)) + "\n")


@pytest.mark.parametrize(
    "fname, edit, message",
    [
        ("raceline.csv", lambda ls: ["s,x,y"] + ls[1:], "columns"),
        ("raceline.csv", lambda ls: ls[:5] + [ls[5].replace(",", ",abc,", 1).rsplit(",", 1)[0]] + ls[6:], "non-numeric"),
        ("raceline.csv", lambda ls: ls[:5] + ["nan" + ls[5][ls[5].index(","):]] + ls[6:], "non-finite"),
        ("raceline.csv", lambda ls: ls[:5] + [ls[5] + ",1.0"] + ls[6:], "fields"),
        ("raceline.csv", lambda ls: ls[:4] + [ls[5], ls[4]] + ls[6:], "increasing"),
        ("raceline.csv", lambda ls: ls[:6], "rows"),
        ("left_edge.csv", lambda ls: ls[:1] + [ls[1].replace(",", ";")] + ls[2:], "left_edge.csv"),
        ("right_edge.csv", lambda ls: ls[:3], "rows"),
        ("meta.json", lambda ls: ["{not json"], "JSON"),
    ],
)
def test_malformed_file_names_the_file(tmp_path, fname, edit, message):
    folder = copy_circuit(SOURCE, tmp_path)
    _edit_lines(folder / fname, edit)
    with pytest.raises(TrackFormatError) as info:
        Track.load(folder)
    assert fname in str(info.value)
    assert message.lower() in str(info.value).lower()


def test_wrong_format_version(tmp_path):
    folder = copy_circuit(SOURCE, tmp_path)
    meta = json.loads((folder / "meta.json").read_text())
    meta["format_version"] = 99
    (folder / "meta.json").write_text(json.dumps(meta))
    with pytest.raises(TrackFormatError, match="meta.json.*format_version"):
        Track.load(folder)


def test_length_inconsistent_with_s(tmp_path):
    folder = copy_circuit(SOURCE, tmp_path)
    meta = json.loads((folder / "meta.json").read_text())
    meta["length_m"] = 100.0
    (folder / "meta.json").write_text(json.dumps(meta))
    with pytest.raises(TrackFormatError, match="raceline.csv"):
        Track.load(folder)
