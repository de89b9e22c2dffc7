"""End-to-end tests of the circuit builder (sofar_env.tracks.builder.pipeline) on small synthetic
circuits: edges or centreline file -> Track."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from synthetic_circuits import R, circle, write_edges

from sofar_env.tracks import BuildConfig, build_track
from sofar_env.tracks.builder import polyline_distance


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


def test_unknown_source_format_raises(tmp_path):
    src = tmp_path / "circle.csv"
    write_edges(src, circle(R - 1.5, 150), circle(R + 1.5, 170))
    with pytest.raises(ValueError, match="format"):
        build_track(src, "X", source_format="gpx")
