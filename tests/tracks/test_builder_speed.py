"""Tests of the speed profile of the circuit builder (sofar_env.tracks.builder.speed)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sofar_env.tracks.builder import lap_time, speed_profile


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


def test_lap_time_with_constant_acceleration_between_samples():
    ds = np.array([10.0, 30.0, 20.0])
    v = np.array([10.0, 20.0, 30.0])
    # each segment at the mean of its end speeds; the last one closes the loop (30 -> 10)
    assert lap_time(v, ds) == pytest.approx(10.0 / 15.0 + 30.0 / 25.0 + 20.0 / 20.0)
    assert lap_time(np.full(4, 5.0), np.full(4, 2.5)) == pytest.approx(2.0)
