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
