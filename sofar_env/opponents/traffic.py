"""Opponents among themselves along the track: following, passing only where two cars fit, yielding.

For every pair with car ``i`` behind car ``j`` (``0 < g = s_j - s_i``, or ``g = 0`` and
``i > j``; within reach of this step) the arc-length advance ``ds_i`` of ``i`` in one step is limited:

* same lateral band (offsets closer than the band width): ``i`` does not close
  below ``follow_gap``, ``ds_i <= ds_j + max(g - follow_gap, 0)`` (it matches ``j``'s
  speed there);
* different bands, ``i`` not yet alongside (``g >= car length + margin``): ``i``
  may pass only when it is closing by at least 1 m/s and the soft band stays wide
  enough for both cars over the distance the pass takes at half the current closing
  speed; otherwise it follows as in the same band;
* alongside in different bands, and the track ahead (2 s) too narrow for two cars:
  ``i`` yields, braking at ``YIELD_DECEL``;
* a car *squeezed* in the last lateral step (no room beside a neighbour or the ego,
  :mod:`~sofar_env.opponents.steering`) brakes at ``YIELD_DECEL`` as well.

The limits only decrease the advances, so the sweep over the pairs is repeated to a
fixed point (at most ``m`` sweeps).
"""

from __future__ import annotations

import numpy as np

from .config import TrafficConfig
from .lateral import EdgeBand

__all__ = ["YIELD_DECEL", "limit_advances"]

YIELD_DECEL = 6.0
"""Braking of a car that yields to one alongside when the track narrows [m/s^2]."""

_MIN_PASS_CLOSING = 1.0
"""Smallest closing speed at which a car starts to pass another opponent [m/s]."""

_PASS_ROOM_MARGIN = 0.5
"""Two cars fit side by side where the soft band is this much wider than the band width [m]."""

_SQUEEZE_TIME = 2.0
"""A car alongside another checks the track this far ahead for room for both [s]."""

_MAX_PASS_DISTANCE = 2000.0
"""Longest pass considered [m]."""


def limit_advances(ds: list[float], s: list[float], n: list[float], v: list[float], gap: np.ndarray, dt: float,
                   band: EdgeBand, cfg: TrafficConfig, band_width: float, alongside: float,
                   squeezed: list[bool] | None = None) -> list[bool]:
    """Limit the advances ``ds`` [m] of one step in place; returns which were limited.

    ``s, n, v``: start-of-step arc length, offset and arc-length speed of every car;
    ``gap[i, j] = s_j - s_i`` (periodic); ``band_width``: centre-to-centre offset below which two cars
    are in the same band [m]; ``alongside``: gap below which two cars are alongside [m]; ``squeezed``:
    the cars that found no room beside a neighbour in the last lateral step (they yield).
    """
    m = len(ds)
    follow = cfg.follow_gap
    need = band_width + _PASS_ROOM_MARGIN
    rules = []  # (i, j, g) follow rules; yields are applied at once
    capped = [False] * m
    for i in range(m):
        if squeezed is not None and squeezed[i]:
            _brake(ds, capped, i, v[i], dt)
    for i in range(m):
        for j in range(m):
            g = float(gap[i, j])
            # i is behind j (a tie counts the higher index as behind)
            if i == j or not (0.0 < g or (g == 0.0 and i > j)) or g >= follow + ds[i]:
                continue
            if abs(n[i] - n[j]) < band_width:
                rules.append((i, j, g))
            elif g >= alongside:
                closing = v[i] - v[j]
                if closing < _MIN_PASS_CLOSING:
                    rules.append((i, j, g))
                    continue
                distance = min(v[i] * (g + alongside) / (0.5 * closing) + alongside, _MAX_PASS_DISTANCE)
                if band.room(s[i], distance) < need:
                    rules.append((i, j, g))
            elif band.room(s[i], v[i] * _SQUEEZE_TIME + alongside) < need:
                _brake(ds, capped, i, v[i], dt)
    for _ in range(m):  # the caps only decrease: a fixed point within m sweeps
        changed = False
        for i, j, g in rules:
            cap = max(ds[j] + max(g - follow, 0.0), 0.0)
            if ds[i] > cap:
                ds[i], capped[i], changed = cap, True, True
        if not changed:
            break
    return capped


def _brake(ds: list[float], capped: list[bool], i: int, v: float, dt: float) -> None:
    """Limit the advance of car ``i`` to braking at ``YIELD_DECEL`` from its speed ``v``."""
    cap = dt * max(v - YIELD_DECEL * dt, 0.0)
    if ds[i] > cap:
        ds[i], capped[i] = cap, True
