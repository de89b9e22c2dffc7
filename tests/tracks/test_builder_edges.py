"""Tests of the edge preparation and centreline stage (sofar_env.tracks.builder.edges)."""

from __future__ import annotations

import numpy as np
import pytest
from synthetic_circuits import R, circle

from sofar_env.tracks.builder import BuildConfig
from sofar_env.tracks.builder.edges import centerline, orient_edges, prepare_edge
from sofar_env.tracks.builder.polyline import signed_area

CENTRE = np.array([10.0, -5.0])


@pytest.mark.parametrize("left_ccw, right_ccw", [(True, True), (True, False), (False, False), (False, True)])
def test_orientation_follows_the_left_right_labels(left_ccw, right_ccw):
    """Inner edge labelled left: counter-clockwise driving, whatever the point order."""
    left, right = orient_edges(circle(R - 3, 50, ccw=left_ccw), circle(R + 3, 70, ccw=right_ccw))
    assert signed_area(left) > 0 and signed_area(right) > 0
    # outer edge labelled left: clockwise driving
    left, right = orient_edges(circle(R + 3, 50, ccw=left_ccw), circle(R - 3, 70, ccw=right_ccw))
    assert signed_area(left) < 0 and signed_area(right) < 0


def test_prepare_edge_resamples_and_reports_the_smoothing_shift():
    cfg = BuildConfig()
    edge, shift = prepare_edge(circle(R, 90), cfg)
    steps = np.hypot(*np.diff(np.vstack([edge, edge[:1]]), axis=0).T)
    assert steps.mean() == pytest.approx(cfg.spacing, rel=0.01)
    assert 0.0 < shift < 0.05
    raw, none = prepare_edge(circle(R, 90), BuildConfig(edge_smoothing=0.0))
    assert none == 0.0 and len(raw) == len(edge)


def test_centerline_is_equidistant_from_the_edges():
    cfg = BuildConfig()
    left, _ = prepare_edge(circle(R - 2.0, 150, phase=0.3), cfg)
    right, _ = prepare_edge(circle(R + 4.0, 233, phase=2.0), cfg)
    center = centerline(left, right, cfg)
    np.testing.assert_allclose(np.hypot(*(center - CENTRE).T), R + 1.0, atol=0.02)
    steps = np.hypot(*np.diff(np.vstack([center, center[:1]]), axis=0).T)
    assert steps.mean() == pytest.approx(cfg.qp_spacing, rel=0.01)
