"""Tests of the closed-polyline geometry of the circuit builder (sofar_env.tracks.builder.polyline)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from synthetic_circuits import R, circle

from sofar_env.tracks import TrackFormatError
from sofar_env.tracks.builder.polyline import (
    clean_closed,
    closest_points,
    edge_widths,
    periodic_smooth,
    polyline_distance,
    ray_polyline_distance,
    resample_closed,
    signed_area,
    spline_resample_closed,
    tangent_normal,
)

SQUARE = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]])  # counter-clockwise


def test_clean_closed_drops_repeats_and_non_finite_rows():
    pts = np.vstack([circle(R, 12), [[np.nan, 1.0]]])
    pts = np.insert(pts, 3, pts[2], axis=0)  # a repeated point
    pts = np.vstack([pts[:-1], pts[:1]])     # the closing point repeated
    np.testing.assert_array_equal(clean_closed(pts, "x"), circle(R, 12))
    with pytest.raises(TrackFormatError, match="lbl"):
        clean_closed(circle(R, 7), "lbl")


def test_signed_area_and_orientation():
    assert signed_area(SQUARE) == pytest.approx(100.0)
    assert signed_area(SQUARE[::-1]) == pytest.approx(-100.0)


def test_distances_to_a_square():
    pts = np.array([[5.0, 5.0], [12.0, 5.0], [13.0, 14.0], [5.0, 0.0]])
    np.testing.assert_allclose(polyline_distance(pts, SQUARE), [5.0, 2.0, 5.0, 0.0])
    np.testing.assert_allclose(closest_points(pts, SQUARE), [[5.0, 0.0], [10.0, 5.0], [10.0, 10.0], [5.0, 0.0]],
                               atol=1e-12)
    origins = np.array([[5.0, 5.0], [5.0, 5.0], [20.0, 5.0]])
    directions = np.array([[1.0, 0.0], [0.0, -1.0], [1.0, 0.0]])
    np.testing.assert_allclose(ray_polyline_distance(origins, directions, SQUARE), [5.0, 5.0, np.inf])


def test_uniform_resampling_of_a_circle():
    pts = circle(R, 37)
    lin = resample_closed(pts, 2.0)
    steps = np.hypot(*np.diff(np.vstack([lin, lin[:1]]), axis=0).T)
    assert np.ptp(steps) < 0.05 and steps.mean() == pytest.approx(2.0, rel=0.02)
    fine, length = spline_resample_closed(pts, 1.0)
    assert length == pytest.approx(2 * math.pi * R, rel=1e-5)  # the spline is close to the circle
    steps = np.hypot(*np.diff(np.vstack([fine, fine[:1]]), axis=0).T)
    np.testing.assert_allclose(steps, length / len(fine), rtol=1e-4)


def test_periodic_smooth_removes_ripples_and_keeps_the_circle():
    pts = circle(R, 400)
    tangent, normal = tangent_normal(pts)
    np.testing.assert_allclose(np.hypot(*tangent.T), 1.0)
    np.testing.assert_allclose(normal, np.column_stack([-tangent[:, 1], tangent[:, 0]]))
    rippled = pts + (0.05 * (-1.0) ** np.arange(400))[:, None] * normal
    smooth = periodic_smooth(rippled, 10.0)
    np.testing.assert_allclose(np.hypot(*(smooth - [10.0, -5.0]).T), R, atol=5e-3)


def test_edge_widths_along_the_normals():
    pts = circle(R, 100)
    _, normal = tangent_normal(pts)  # left normal: inwards on a counter-clockwise circle
    wl, wr = edge_widths(pts, normal, circle(R - 2.0, 300), circle(R + 3.0, 310))
    # up to the sagitta of the polygon edges, R (1 - cos(pi / count)) < 4 mm
    np.testing.assert_allclose(wl, 2.0, atol=4e-3)
    np.testing.assert_allclose(wr, 3.0, atol=4e-3)
