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

from .._jit import kernel, py_max, py_min
from .config import TrafficConfig
from .lateral import EdgeBand, room_at

__all__ = ["YIELD_DECEL", "limit_advances", "limit_advances_at"]

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


def limit_advances(ds, s, n, v, gap: np.ndarray, dt: float, band: EdgeBand, cfg: TrafficConfig, band_width: float,
                   alongside: float, squeezed=None) -> np.ndarray:
    """Limit the advances ``ds`` [m] of one step (an array, changed in place); returns which were limited.

    ``s, n, v``: start-of-step arc length, offset and arc-length speed of every car;
    ``gap[i, j] = s_j - s_i`` (periodic); ``band_width``: centre-to-centre offset below which two cars
    are in the same band [m]; ``alongside``: gap below which two cars are alongside [m]; ``squeezed``:
    the cars that found no room beside a neighbour in the last lateral step (they yield).
    One compiled call (:func:`limit_advances_at`).
    """
    if not (isinstance(ds, np.ndarray) and ds.dtype == np.float64):
        raise TypeError(f"ds must be a float64 numpy array (it is changed in place), got {type(ds).__name__}")
    m = len(ds)
    squeezed = np.zeros(m, dtype=np.bool_) if squeezed is None else np.asarray(squeezed, dtype=np.bool_)
    capped = np.zeros(m, dtype=np.bool_)
    knots, soft_lo, soft_hi, _, _, length = band.envelope_data()
    limit_advances_at(ds, np.asarray(s, dtype=float), np.asarray(n, dtype=float), np.asarray(v, dtype=float),
                      np.ascontiguousarray(gap, dtype=float), float(dt), squeezed, cfg.follow_gap, float(band_width),
                      float(alongside), knots, soft_lo, soft_hi, length, capped)
    return capped


@kernel
def limit_advances_at(ds, s, n, v, gap, dt, squeezed, follow, band_width, alongside, knots, soft_lo, soft_hi, length,
                      capped):
    """:func:`limit_advances` on arrays (``knots, soft_lo, soft_hi, length``: the soft band of
    :meth:`EdgeBand.envelope_data`); writes ``ds`` and ``capped``."""
    m = ds.shape[0]
    need = band_width + _PASS_ROOM_MARGIN
    # follow rules (i behind j at gap g); yields are applied at once
    rule_i = np.empty(m * m, dtype=np.int64)
    rule_j = np.empty(m * m, dtype=np.int64)
    rule_g = np.empty(m * m)
    n_rules = 0
    for i in range(m):
        capped[i] = False
    for i in range(m):
        if squeezed[i]:
            _brake(ds, capped, i, v[i], dt)
    for i in range(m):
        for j in range(m):
            g = gap[i, j]
            # i is behind j (a tie counts the higher index as behind)
            if i == j or not (0.0 < g or (g == 0.0 and i > j)) or g >= follow + ds[i]:
                continue
            rule = False
            if abs(n[i] - n[j]) < band_width:
                rule = True
            elif g >= alongside:
                closing = v[i] - v[j]
                if closing < _MIN_PASS_CLOSING:
                    rule = True
                else:
                    distance = py_min(v[i] * (g + alongside) / (0.5 * closing) + alongside, _MAX_PASS_DISTANCE)
                    rule = room_at(s[i], distance, knots, soft_lo, soft_hi, length) < need
            elif room_at(s[i], v[i] * _SQUEEZE_TIME + alongside, knots, soft_lo, soft_hi, length) < need:
                _brake(ds, capped, i, v[i], dt)
            if rule:
                rule_i[n_rules], rule_j[n_rules], rule_g[n_rules] = i, j, g
                n_rules += 1
    for _ in range(m):  # the caps only decrease: a fixed point within m sweeps
        changed = False
        for r in range(n_rules):
            i, j, g = rule_i[r], rule_j[r], rule_g[r]
            cap = py_max(ds[j] + py_max(g - follow, 0.0), 0.0)
            if ds[i] > cap:
                ds[i], capped[i], changed = cap, True, True
        if not changed:
            break


@kernel
def _brake(ds, capped, i, v, dt):
    """Limit the advance of car ``i`` to braking at ``YIELD_DECEL`` from its speed ``v``."""
    cap = dt * py_max(v - YIELD_DECEL * dt, 0.0)
    if ds[i] > cap:
        ds[i], capped[i] = cap, True
