"""Speed profile of a closed raceline: a forward-backward pass, and its lap time.

The profile is the fastest one that keeps the lateral acceleration ``v^2 |kappa|``
within ``a_lat_max``, the speed within ``top_speed`` and the acceleration between
samples, ``(v_{i+1}^2 - v_i^2) / (2 ds_i)``, within ``[-a_brake_max, a_accel_max]``:
the curvature limit, then forward (acceleration) and backward (braking) passes
around the closed loop, repeated until nothing changes (at most 10 rounds).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["speed_profile", "lap_time"]


def speed_profile(
    kappa: np.ndarray, ds: np.ndarray, a_lat_max: float, a_accel_max: float, a_brake_max: float, top_speed: float
) -> np.ndarray:
    """Closed-loop speed profile.

    ``ds[i]`` is the arc length from sample i to sample i+1 (the last entry
    closes the loop).  Enforces v^2 |kappa| <= a_lat_max, v <= top_speed and
    (v_{i+1}^2 - v_i^2) / (2 ds_i) in [-a_brake_max, a_accel_max].
    """
    kappa = np.asarray(kappa, dtype=float)
    with np.errstate(divide="ignore"):
        vmax = np.where(np.abs(kappa) > 1e-12, np.sqrt(a_lat_max / np.abs(kappa)), np.inf)
    vmax = np.minimum(vmax, top_speed)
    n = len(vmax)
    start = int(np.argmin(vmax))  # this sample is never lowered by the passes below
    v = np.roll(vmax, -start).tolist()
    d = np.roll(np.asarray(ds, dtype=float), -start).tolist()
    for _ in range(10):
        before = list(v)
        for j in range(n):  # acceleration limit, forward
            k = (j + 1) % n
            reach = math.sqrt(v[j] * v[j] + 2.0 * a_accel_max * d[j])
            if v[k] > reach:
                v[k] = reach
        for j in range(n - 1, -1, -1):  # braking limit, backward
            k = (j + 1) % n
            reach = math.sqrt(v[k] * v[k] + 2.0 * a_brake_max * d[j])
            if v[j] > reach:
                v[j] = reach
        if v == before:
            break
    return np.roll(np.array(v), start)


def lap_time(v: np.ndarray, ds: np.ndarray) -> float:
    """Lap time of a closed speed profile with constant acceleration between samples [s]."""
    return float(np.sum(2.0 * ds / (v + np.roll(v, -1))))
