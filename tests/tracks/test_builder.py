"""Tests of the circuit builder on small synthetic circuits."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from sofar_env.tracks import BuildConfig, Track, TrackFormatError, build_track
from sofar_env.tracks.__main__ import main as cli_main
from sofar_env.tracks.builder import polyline_distance, speed_profile

R = 60.0  # [m] radius of the synthetic circles


def circle(radius: float, count: int, phase: float = 0.0, ccw: bool = True, center=(10.0, -5.0)) -> np.ndarray:
    ang = phase + np.linspace(0.0, 2.0 * math.pi, count, endpoint=False)
    if not ccw:
        ang = ang[::-1]
    return np.column_stack([center[0] + radius * np.cos(ang), center[1] + radius * np.sin(ang)])


def write_edges(path, left: np.ndarray, right: np.ndarray) -> None:
    """Edges CSV without header; the edges have different sample counts (NaN padding)."""
    rows = max(len(left), len(right))
    data = np.full((rows, 4), np.nan)
    data[: len(left), :2] = left
    data[: len(right), 2:] = right
    lines = [",".join("" if math.isnan(v) else f"{v:.6f}" for v in row) for row in data]
    path.write_text("\n".join(lines) + "\n")


def test_ccw_circle_from_edges_centred_in_narrow_corridor(tmp_path):
    # Corridor 3 m wide < 2 x clearance: the raceline is centred (radius R) and a warning is issued.
    src = tmp_path / "circle.csv"
    write_edges(src, circle(R - 1.5, 150, phase=0.3), circle(R + 1.5, 233, phase=2.0))
    with pytest.warns(UserWarning, match="narrower"):
        track = build_track(src, "Circle", tmp_path / "Circle")
    assert track.meta["driving_direction"] == "counter-clockwise"
    assert np.allclose(track.kappa, 1.0 / R, rtol=2e-3)
    assert track.curvature(12.3) == pytest.approx(1.0 / R, rel=2e-3)
    assert track.length == pytest.approx(2 * math.pi * R, rel=1e-3)
    # centred up to the 5 cm of slack the builder leaves in too narrow corridors
    assert np.allclose(track.w_left, 1.5, atol=0.06) and np.allclose(track.w_right, 1.5, atol=0.06)
    # speed limited by the lateral acceleration: v = sqrt(15 R)
    assert np.allclose(track.v, math.sqrt(15.0 * R), rtol=3e-3)
    assert track.meta["lap_time_s"] == pytest.approx(track.length / math.sqrt(15.0 * R), rel=3e-3)


def test_cw_circle_from_edges_has_negative_curvature(tmp_path):
    # Clockwise: the left edge is the outside.  Wide track: the line hugs the outer bound.
    src = tmp_path / "cw.csv"
    write_edges(src, circle(R + 5.0, 301, ccw=False), circle(R - 5.0, 197, phase=1.0, ccw=False))
    track = build_track(src, "CW", config=BuildConfig(clearance=2.0))
    assert track.meta["driving_direction"] == "clockwise"
    assert np.all(track.kappa < 0)
    # minimum curvature = largest radius allowed: R + 5 - clearance (- the small QP margin)
    radius = 1.0 / np.abs(track.kappa)
    assert np.allclose(radius, R + 3.0, atol=0.2)
    assert np.allclose(track.w_left, 2.0, atol=0.1)
    assert np.std(radius) < 0.1
    _, n_left = track.to_frenet(*circle(R + 5.0, 50).T)
    assert np.all(n_left > 0)


def test_edges_listed_against_driving_direction_are_reoriented(tmp_path):
    # Left edge (inside, CCW driving) given in clockwise order: labels decide the direction.
    src = tmp_path / "rev.csv"
    write_edges(src, circle(R - 1.5, 120, ccw=False), circle(R + 1.5, 140, ccw=False))
    with pytest.warns(UserWarning, match="narrower"):
        track = build_track(src, "Rev")
    assert track.meta["driving_direction"] == "counter-clockwise"
    assert np.allclose(track.kappa, 1.0 / R, rtol=2e-3)


def test_ccw_circle_from_centerline_format(tmp_path):
    c = circle(R, 180, phase=0.5)
    src = tmp_path / "center.csv"
    rows = [f"{x:.6f},{y:.6f},1.5,1.5" for x, y in c]
    src.write_text("# x_m,y_m,w_tr_right_m,w_tr_left_m\n" + "\n".join(rows) + "\n")
    with pytest.warns(UserWarning, match="narrower"):
        track = build_track(src, "CenterCircle", tmp_path / "out", source_format="centerline")
    assert track.meta["source"]["format"] == "centerline"
    assert np.allclose(track.kappa, 1.0 / R, rtol=2e-3)
    assert np.allclose(track.w_left, 1.5, atol=0.06) and np.allclose(track.w_right, 1.5, atol=0.06)


def test_ellipse_raceline_keeps_clearance_and_limits(tmp_path):
    t = np.linspace(0.0, 2 * math.pi, 400, endpoint=False)
    center = np.column_stack([170.0 * np.cos(t), 70.0 * np.sin(t)])
    tangent = np.column_stack([-170.0 * np.sin(t), 70.0 * np.cos(t)])
    tangent /= np.hypot(*tangent.T)[:, None]
    normal = np.column_stack([-tangent[:, 1], tangent[:, 0]])
    left, right = center + 6.0 * normal, center - 6.0 * normal
    src = tmp_path / "ellipse.csv"
    write_edges(src, left, right[::2])
    config = BuildConfig(clearance=2.5, top_speed=50.0)
    track = build_track(src, "Ellipse", tmp_path / "Ellipse", config=config)
    ds = track.length / len(track.s)
    s = np.concatenate([track.s, track.s + 0.5 * ds])
    pts = np.column_stack(track.to_cartesian(s, 0.0))
    assert polyline_distance(pts, track.left_edge).min() >= 2.5 - 0.01
    assert polyline_distance(pts, track.right_edge).min() >= 2.5 - 0.01
    # a minimum-curvature line on an ellipse: less peak curvature than the centreline
    center_peak = 170.0 / 70.0**2
    assert np.max(np.abs(track.kappa)) < 0.9 * center_peak
    assert np.all(track.kappa > 0)
    v = track.v
    assert v.max() <= 50.0 + 1e-9
    assert np.max(v * v * np.abs(track.kappa)) <= 15.0 + 1e-6
    acc = (np.roll(v, -1) ** 2 - v**2) / (2.0 * np.diff(np.append(track.s, track.length)))
    assert acc.max() <= 3.0 + 1e-6 and acc.min() >= -10.0 - 1e-6
    meta = json.loads((tmp_path / "Ellipse" / "meta.json").read_text())
    assert meta["builder"]["clearance"] == 2.5 and len(meta["source"]["sha256"]) == 64


def test_speed_profile_closed_loop():
    n = 400
    kappa = np.full(n, 1e-4)
    kappa[100:110] = 0.05  # one slow corner
    ds = np.full(n, 2.0)
    v = speed_profile(kappa, ds, 15.0, 3.0, 10.0, 85.0)
    assert np.max(v * v * np.abs(kappa)) <= 15.0 + 1e-9
    acc = (np.roll(v, -1) ** 2 - v**2) / (2.0 * ds)
    assert acc.max() <= 3.0 + 1e-9 and acc.min() >= -10.0 - 1e-9
    assert v[100] == pytest.approx(math.sqrt(15.0 / 0.05))
    assert v.max() <= 85.0
    # braking before the corner wraps around the start of the loop correctly
    assert np.argmax(v) < 100 or np.argmax(v) > 110
    # constant curvature: constant speed
    assert np.allclose(speed_profile(np.full(50, 0.01), np.ones(50), 15.0, 3.0, 10.0, 85.0), math.sqrt(1500.0))


def test_source_errors_name_the_file(tmp_path):
    with pytest.raises(TrackFormatError, match="nothere.csv"):
        build_track(tmp_path / "nothere.csv", "X")
    bad = tmp_path / "bad.csv"
    bad.write_text("1,2,3\n4,5,6\n")
    with pytest.raises(TrackFormatError, match="bad.csv"):
        build_track(bad, "X")
    text = tmp_path / "text.csv"
    text.write_text("1,2,3,4\n5,6,x,8\n")
    with pytest.raises(TrackFormatError, match="text.csv"):
        build_track(text, "X")
    with pytest.raises(ValueError, match="format"):
        build_track(bad, "X", source_format="gpx")


def test_cli_build_and_info(tmp_path, capsys):
    src = tmp_path / "circle.csv"
    write_edges(src, circle(R - 1.5, 150), circle(R + 1.5, 170))
    out = tmp_path / "Cli"
    with pytest.warns(UserWarning):
        assert cli_main(["build", str(src), "--name", "Cli", "--out", str(out), "--top-speed", "20"]) == 0
    for fname in ("raceline.csv", "left_edge.csv", "right_edge.csv", "centerline.csv", "meta.json"):
        assert (out / fname).is_file()
    track = Track.load(out)
    assert track.name == "Cli" and track.max_speed == pytest.approx(20.0)
    assert cli_main(["info", str(out)]) == 0
    assert "Cli" in capsys.readouterr().out
