"""Tests of the builder's files (sofar_env.tracks.builder.io): input readers and the circuit folder."""

from __future__ import annotations

import hashlib
import json

import numpy as np
import pytest
from synthetic_circuits import R, circle, write_edges

from sofar_env.tracks import Track, TrackFormatError
from sofar_env.tracks.builder import (
    CENTERLINE_FILE,
    BuiltCircuit,
    read_centerline_csv,
    read_edges_csv,
    write_circuit,
)
from sofar_env.tracks.builder.io import sha256


def test_source_errors_name_the_file(tmp_path):
    with pytest.raises(TrackFormatError, match="nothere.csv"):
        read_edges_csv(tmp_path / "nothere.csv")
    bad = tmp_path / "bad.csv"
    bad.write_text("1,2,3\n4,5,6\n")
    with pytest.raises(TrackFormatError, match="bad.csv"):
        read_edges_csv(bad)
    text = tmp_path / "text.csv"
    text.write_text("1,2,3,4\n5,6,x,8\n")
    with pytest.raises(TrackFormatError, match="text.csv"):
        read_centerline_csv(text)
    few = tmp_path / "few.csv"
    write_edges(few, circle(R, 5), circle(R + 3, 20))
    with pytest.raises(TrackFormatError, match="fewer than 8"):
        read_edges_csv(few)


def test_edges_reader_skips_header_padding_and_the_closing_point(tmp_path):
    left, right = circle(R - 1.5, 40), circle(R + 1.5, 55)
    src = tmp_path / "edges.csv"
    write_edges(src, np.vstack([left, left[:1]]), right)  # closing point repeated, NaN padding
    src.write_text("# comment\nleft_x,left_y,right_x,right_y\n" + src.read_text())
    got_left, got_right = read_edges_csv(src)
    np.testing.assert_allclose(got_left, left, atol=1e-6)
    np.testing.assert_allclose(got_right, right, atol=1e-6)


def test_centerline_reader_offsets_along_the_left_normal(tmp_path):
    c = circle(R, 90)
    src = tmp_path / "center.csv"
    src.write_text("\n".join(f"{x:.6f},{y:.6f},2.0,1.0" for x, y in c) + "\n")  # w_right 2, w_left 1
    left, right = read_centerline_csv(src)
    centre = np.array([10.0, -5.0])
    # counter-clockwise: the left normal points inwards
    np.testing.assert_allclose(np.hypot(*(left - centre).T), R - 1.0, atol=1e-3)
    np.testing.assert_allclose(np.hypot(*(right - centre).T), R + 2.0, atol=1e-3)
    src.write_text("\n".join(f"{x:.6f},{y:.6f},0.0,1.0" for x, y in c) + "\n")
    with pytest.raises(TrackFormatError, match="positive"):
        read_centerline_csv(src)


def test_sha256_of_a_file(tmp_path):
    path = tmp_path / "x.bin"
    path.write_bytes(b"sofar" * 30000)
    assert sha256(path) == hashlib.sha256(b"sofar" * 30000).hexdigest()


def test_written_folder_loads_back(tmp_path):
    n = 64
    s = np.arange(n) * (2 * np.pi * R / n)
    pts = circle(R, n)
    psi = np.arctan2(pts[:, 1] + 5.0, pts[:, 0] - 10.0) + np.pi / 2
    raceline = np.column_stack([s, pts, psi, np.full(n, 1 / R), np.full(n, 2.0), np.full(n, 2.0), np.full(n, 30.0)])
    meta = {"format_version": 1, "name": "Ring", "length_m": round(2 * np.pi * R, 6)}
    built = BuiltCircuit(raceline, circle(R - 2, 80), circle(R + 2, 90), np.zeros((3, 5)), meta)
    folder = write_circuit(tmp_path / "Ring", built)
    assert (folder / CENTERLINE_FILE).is_file()
    assert json.loads((folder / "meta.json").read_text())["name"] == "Ring"
    track = Track.load(folder)
    assert track.name == "Ring" and len(track.s) == n
    np.testing.assert_allclose(track.v, 30.0)
