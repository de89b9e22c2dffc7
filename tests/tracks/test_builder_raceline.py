"""Tests of the minimum-curvature raceline stage (sofar_env.tracks.builder.raceline)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from synthetic_circuits import R

from sofar_env.tracks.builder import BuildConfig
from sofar_env.tracks.builder.edges import centerline, prepare_edge
from sofar_env.tracks.builder.polyline import polyline_distance
from sofar_env.tracks.builder.raceline import fit_raceline


def ellipse_edges(half_width: float):
    t = np.linspace(0.0, 2 * math.pi, 400, endpoint=False)
    center = np.column_stack([170.0 * np.cos(t), 70.0 * np.sin(t)])
    tangent = np.column_stack([-170.0 * np.sin(t), 70.0 * np.cos(t)])
    tangent /= np.hypot(*tangent.T)[:, None]
    normal = np.column_stack([-tangent[:, 1], tangent[:, 0]])
    return center + half_width * normal, center - half_width * normal


def fit(left, right, config):
    left_s, _ = prepare_edge(left, config)
    right_s, _ = prepare_edge(right, config)
    center = centerline(left_s, right_s, config)
    anchor = 0.5 * (left[0] + right[0])
    return fit_raceline(center, left_s, right_s, left, right, anchor, "test", config), left_s, right_s, center


def test_raceline_keeps_the_clearance_and_lowers_the_peak_curvature():
    config = BuildConfig(clearance=2.5)
    left, right = ellipse_edges(6.0)
    race, left_s, right_s, _ = fit(left, right, config)
    assert not race.narrow.any()
    assert race.s[0] == 0.0 and race.s[-1] < race.length
    n = len(race.s)
    assert race.check_points.shape == (2 * n, 2)
    for edge in (left, right, left_s, right_s):  # stored and source edges, samples and mid-points
        assert polyline_distance(race.check_points, edge).min() >= config.clearance - 1e-9
    np.testing.assert_allclose(race.d_left, polyline_distance(race.check_points, left_s))
    # the line uses the corridor (somewhere near an edge) to lower the peak curvature
    assert min(race.d_left.min(), race.d_right.min()) < config.clearance + 0.1
    _, _, dx, dy, ddx, ddy = race.curve.eval(race.s, order=2)
    kappa = (dx * ddy - dy * ddx) / np.power(dx * dx + dy * dy, 1.5)
    assert np.all(kappa > 0) and kappa.max() < 0.9 * 170.0 / 70.0**2  # the centreline's peak
    x, y, _, _ = race.curve.eval(race.s[:1])
    assert np.hypot(x[0] - 0.5 * (left[0, 0] + right[0, 0]), y[0] - 0.5 * (left[0, 1] + right[0, 1])) < 6.0


def test_narrow_corridor_is_flagged_and_centred():
    t = np.linspace(0.0, 2 * math.pi, 300, endpoint=False)
    ring = np.column_stack([np.cos(t), np.sin(t)])
    race, *_ = fit(ring * (R - 1.5), ring * (R + 1.5), BuildConfig())
    assert race.narrow.all()
    np.testing.assert_allclose(np.hypot(*race.check_points.T), R, atol=0.06)


def test_unreachable_clearance_raises():
    left, right = ellipse_edges(6.0)
    # a QP margin below zero (fit_raceline itself does not validate the configuration) leaves
    # the first solution short of the clearance; without repair rounds that is an error
    with pytest.raises(RuntimeError, match="test: raceline clearance"):
        fit(left, right, BuildConfig(clearance=2.5, qp_margin=-0.5, max_repairs=0))
