"""Footprint-aware track edges (sofar_env.stack.edges)."""

from __future__ import annotations

import math

import numpy as np

from sofar_env.stack.edges import TrackEdges
from sofar_env.vehicle import AV21


def test_footprint_edges_are_the_narrowest_within_the_car_length(tracks):
    track = tracks["LagunaSeca"]
    s = np.linspace(0.0, track.length, 400, endpoint=False)
    plain = TrackEdges(track, AV21, footprint_aware=False)
    aware = TrackEdges(track, AV21, footprint_aware=True)
    n_min0, n_max0 = plain(s)
    np.testing.assert_array_equal(n_min0, -track.width_right(s))
    np.testing.assert_array_equal(n_max0, track.width_left(s))
    n_min, n_max = aware(s)
    assert np.all(n_min >= n_min0) and np.all(n_max <= n_max0)
    assert np.any(n_min > n_min0) and np.any(n_max < n_max0)
    for k in range(0, 400, 37):
        ends = s[k] + np.array([-AV21.cg_to_rear, AV21.cg_to_front])
        assert n_max[k] <= min(track.width_left(ends[0]), track.width_left(ends[1]))
        assert -n_min[k] <= min(track.width_right(ends[0]), track.width_right(ends[1]))


def test_mpc_edges_are_tightened_by_the_heading_error_swing(tracks):
    track = tracks["Monza"]
    edges = TrackEdges(track, AV21, footprint_aware=True)
    t = np.linspace(0.0, 2.0, 21)
    s = 500.0 + 40.0 * t
    x_prev = np.zeros((t.size, 5))
    x_prev[:, 2] = 0.1  # constant heading error [rad]
    n_min, n_max = edges(s)
    np.testing.assert_array_equal(edges.for_mpc(s, None, t, 0.1)[0], n_min)
    n_min_m, n_max_m = edges.for_mpc(s, x_prev, t, 0.1)
    swing = max(AV21.cg_to_front, AV21.cg_to_rear) * math.sin(0.1)
    np.testing.assert_allclose(n_min_m, n_min + swing)
    np.testing.assert_allclose(n_max_m, n_max - swing)
    plain = TrackEdges(track, AV21, footprint_aware=False)
    np.testing.assert_array_equal(plain.for_mpc(s, x_prev, t, 0.1)[1], plain(s)[1])


def test_edge_relative_swing_follows_the_edges_direction(tracks):
    """Monza's first chicane (s = 600-610 m), where the left edge diverges from the raceline by 0.1-0.4 m
    per metre. Along the raceline (e = 0) the edge-relative swing is none, as the plain one; a car whose
    heading follows the left edge (e = atan of its slope) keeps the narrowest edge on the left, where the
    plain swing takes 0.2-0.9 m off; on a straight with parallel edges both swings are l |sin e|."""
    track = tracks["Monza"]
    edges = TrackEdges(track, AV21, footprint_aware=True)
    reach = max(AV21.cg_to_front, AV21.cg_to_rear)
    t = np.linspace(0.0, 2.0, 21)
    s = 600.0 + 5.0 * t
    n_min, n_max = edges(s)
    x_prev = np.zeros((t.size, 5))
    np.testing.assert_array_equal(edges.for_mpc(s, x_prev, t, 0.1, edge_relative=True)[1], n_max)
    # heading along the left edge: for_mpc reads the prediction 0.1 s (0.5 m) later
    s_pred = s - 0.5
    slope = edges(s_pred + 0.5)[1] - edges(s_pred - 0.5)[1]
    assert slope.min() > 0.05 and slope.max() > 0.35
    x_prev[:, 2] = np.arctan(slope)
    lo_rel, hi_rel = edges.for_mpc(s, x_prev, t, 0.1, edge_relative=True)
    lo_plain, hi_plain = edges.for_mpc(s, x_prev, t, 0.1)
    np.testing.assert_allclose(hi_rel[:-1], n_max[:-1], atol=0.05)  # (the last point reads past the end)
    assert np.all(n_max - hi_plain > 0.2) and np.max(n_max - hi_plain) > 0.8
    assert np.all(lo_rel >= n_min)
    straight = 4140.0 + 40.0 * t  # edges within 0.014 m per metre of parallel to the raceline
    x_prev[:, 2] = 0.1
    rel = edges.for_mpc(straight, x_prev, t, 0.1, edge_relative=True)
    plain = edges.for_mpc(straight, x_prev, t, 0.1)
    for side in (0, 1):  # |(|sin e - k| - |k|) - |sin e|| <= 2 |k|
        np.testing.assert_allclose(rel[side], plain[side], rtol=0.0, atol=2.0 * reach * 0.014 + 1e-9)
