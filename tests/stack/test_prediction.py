"""Opponent and ego positions along the track (sofar_env.stack.prediction)."""

from __future__ import annotations

import numpy as np
import pytest

from sofar_env.stack.prediction import (OpponentPredictor, braking_positions, ego_node_positions,
                                        relative_opponents)
from sofar_env.vehicle import AV21


def test_relative_opponents_keeps_the_window_nearest_first(tracks):
    track = tracks["Monza"]
    L = track.length
    opponents = np.array([[110.0, 1.0, 30.0], [50.0, -2.0, 20.0], [L - 20.0, 0.5, 25.0], [700.0, 0.0, 10.0],
                          [L - 30.0, 0.0, 10.0]])
    rel = relative_opponents(track, 20.0, opponents, look_behind=45.0, look_ahead=400.0)
    np.testing.assert_allclose(rel, [[30.0, -2.0, 20.0], [-40.0, 0.5, 25.0], [90.0, 1.0, 30.0]], atol=1e-9)
    assert relative_opponents(track, 20.0, np.zeros((0, 3)), 30.0, 400.0).shape == (0, 3)
    np.testing.assert_array_equal(opponents[0], [110.0, 1.0, 30.0])  # the input is not modified


def test_constant_speed_prediction_without_pace_ratio(tracks):
    predict = OpponentPredictor(tracks["Monza"], pace_ratio=False)
    rows = np.array([[10.0, 0.0, 20.0], [-5.0, 1.0, 30.0]])
    t = np.array([0.0, 0.5, 2.0])
    np.testing.assert_array_equal(predict(100.0, rows, t), rows[:, :1] + rows[:, 2:3] * t)
    assert predict(100.0, np.zeros((0, 3)), t).shape == (0, 3)


def test_pace_ratio_prediction_follows_the_speed_profile(tracks):
    """At pace ratio 1 an opponent drives the speed profile: its predicted speed is the profile's at
    its predicted position, so it slows down into corners and keeps going across the lap's end."""
    track = tracks["LagunaSeca"]
    predict = OpponentPredictor(track, pace_ratio=True)
    t = np.linspace(0.0, 3.0, 61)
    for s_opp in (200.0, 1500.0, track.length - 50.0):
        rows = np.array([[s_opp - 100.0, 0.0, float(track.speed(s_opp))]])
        s = predict(100.0, rows, t)[0]
        assert s[0] == pytest.approx(rows[0, 0], abs=1e-9)
        assert np.all(np.diff(s) > 0.0)
        v = np.gradient(s, t)
        np.testing.assert_allclose(v[1:-1], track.speed(100.0 + s[1:-1]), rtol=0.02)
    # a car at half the pace covers about half the distance
    rows = np.array([[100.0, 0.0, float(track.speed(200.0))], [100.0, 0.0, 0.5 * float(track.speed(200.0))]])
    s = predict(100.0, rows, np.array([0.0, 0.4]))
    assert (s[1, 1] - 100.0) == pytest.approx(0.5 * (s[0, 1] - 100.0), rel=0.05)


def test_ego_node_positions_track_the_speed_reference_within_the_limits(tracks):
    track = tracks["Monza"]
    node_dt = 0.15
    t = np.arange(76) * node_dt
    s = ego_node_positions(track, 1000.0, 0.0, t, node_dt, 0.8, AV21)  # from standstill: full throttle
    v = np.diff(s) / node_dt
    assert s[0] == 0.0 and np.all(np.diff(v) <= AV21.a_max * node_dt + 1e-9)
    assert np.diff(v)[0] == pytest.approx(AV21.a_max * node_dt)
    fast = ego_node_positions(track, 1000.0, 150.0, t, node_dt, 0.8, AV21)  # far too fast: full braking
    assert np.diff(np.diff(fast) / node_dt)[0] == pytest.approx(AV21.a_min * node_dt)


def test_braking_positions_stop_at_standstill():
    t = np.arange(10) * 0.5
    s = braking_positions(t, 10.0, 5.0)  # stops after 2 s, 10 m
    np.testing.assert_allclose(s[:5], 10.0 * t[:5] - 2.5 * t[:5] ** 2)
    np.testing.assert_array_equal(s[4:], 10.0)
    np.testing.assert_array_equal(braking_positions(t, -1.0, 5.0), 0.0)
