"""Where the cars are and will be along the track, as the planners see them.

* :func:`relative_opponents`: step 1 of Algorithm 1, the opponents as rows
  ``(gap, n, v)`` with the signed periodic gap to the ego, within the planners' window;
* :class:`OpponentPredictor`: step 2, the opponents' arc lengths over the horizon. The
  paper predicts them at constant speed. With ``pace_prediction`` (an addition of ours)
  each opponent keeps its current pace ratio to the circuit's speed profile instead: cars
  slow down for corners, which a constant-speed prediction misses by several metres over
  a second at a corner entry;
* :func:`lateral_motion`: where a car that is moving across the track will be, from its sensed
  lateral rate (an addition of ours, ``StackConfig.lateral_prediction``);
* :func:`ego_node_positions` and :func:`braking_positions`: the ego's arc length at the
  MIQP nodes, following its speed reference within the acceleration limits, or braking.

All arc lengths returned are relative to the ego at the time of the call [m].
"""

from __future__ import annotations

import math

import numpy as np

from .._interp import interp, interp_at, interp_located, locate, wrap_at
from .._jit import kernel, maximum, minimum
from ..vehicle import VehicleParams
from ._lookup import wrap_mod

__all__ = ["relative_opponents", "lateral_motion", "TravelTime", "OpponentPredictor", "ego_node_positions",
           "braking_positions"]


def relative_opponents(track, ego_s: float, opponents: np.ndarray, look_behind: float,
                       look_ahead: float) -> np.ndarray:
    """Rows (gap, n, v[, n_dot]) of the opponents from ``look_behind`` [m] behind to ``look_ahead`` [m]
    ahead of the ego at arc length ``ego_s``, nearest first; ``opponents`` are rows (s, n, v[, n_dot])
    (the lateral rate column, if given, is kept). The gap is :meth:`~sofar_env.tracks.Track.gap`'s.

    One compiled call (:func:`_window_rows`); two opponents at the same distance (where the order of
    ``np.argsort`` is its own) take the numpy form."""
    opp = np.asarray(opponents, float)
    cols = opp.shape[-1] if opp.ndim == 2 and opp.shape[-1] == 4 else 3
    opp = opp.reshape(-1, cols)
    if opp.shape[0] == 0:
        return np.zeros((0, 3))
    rel, tie = _window_rows(opp, float(ego_s), float(track.length), float(look_behind), float(look_ahead))
    if not tie:
        return rel
    gap = np.asarray(track.gap(opp[:, 0], ego_s), float).reshape(-1)
    keep = (gap >= -look_behind) & (gap <= look_ahead)
    rel = opp[keep]  # a copy (boolean indexing)
    rel[:, 0] = gap[keep]
    return rel[np.argsort(np.abs(rel[:, 0]))]


@kernel
def _window_rows(opp, ego_s, length, look_behind, look_ahead):
    """:func:`relative_opponents`: the rows of ``opp`` whose gap ``wrap(s - ego_s + L/2) - L/2`` (the
    track's, :meth:`~sofar_env.tracks.Track.gap`) is in ``[-look_behind, look_ahead]``, with the gap in
    column 0, sorted by its magnitude (insertion sort); and whether two of them tie (their order is then
    left to the caller)."""
    M, cols = opp.shape
    half = 0.5 * length
    gaps = np.empty(M)
    keys = np.empty(M)
    rows = np.empty(M, dtype=np.int64)
    n = 0
    tie = False
    for i in range(M):
        r = (opp[i, 0] - ego_s + half) % length
        g = (0.0 if r >= length else r) - half
        if g >= -look_behind and g <= look_ahead:
            key = abs(g)
            p = n
            while p > 0 and keys[p - 1] > key:
                keys[p], gaps[p], rows[p] = keys[p - 1], gaps[p - 1], rows[p - 1]
                p -= 1
            tie = tie or (p > 0 and keys[p - 1] == key)
            keys[p], gaps[p], rows[p] = key, g, i
            n += 1
    out = np.empty((n, cols))
    for p in range(n):
        for c in range(cols):
            out[p, c] = opp[rows[p], c]
        out[p, 0] = gaps[p]
    return out, tie


def lateral_motion(track, ego_s: float, opp_rel: np.ndarray, horizon: float, deadband: float,
                   half_width: float) -> tuple[np.ndarray, np.ndarray]:
    """Lateral offset [m] at the end of ``horizon`` [s], and the mean lateral rate [m/s] to it, of the
    opponents ``opp_rel`` (rows (gap, n, v, n_dot) relative to the ego at ``ego_s``).

    Each car keeps moving at its sensed rate shrunk by ``deadband`` [m/s] (a soft threshold:
    ``sign(r) max(|r| - deadband, 0)``), and stops at the edge: its centre stays ``half_width`` [m]
    inside the track at its current arc length (and where it already is, if it is closer to an edge).
    One compiled call (:func:`_lateral_motion`).
    """
    rows = np.ascontiguousarray(opp_rel, dtype=float)
    n_end, rate = np.empty(rows.shape[0]), np.empty(rows.shape[0])
    knots, wl = track.table("wl")
    _lateral_motion(float(ego_s), rows, float(horizon), float(deadband), float(half_width), float(track.length),
                    knots, wl, track.table("wr")[1], n_end, rate)
    return n_end, rate


@kernel
def _lateral_motion(ego_s, opp_rel, horizon, deadband, half_width, length, knots, wl, wr, n_end, rate_out):
    """:func:`lateral_motion` into ``n_end`` and ``rate_out``, with the operations of its numpy form::

        rate = np.sign(r) * np.maximum(np.abs(r) - deadband, 0.0)
        s = track.wrap(ego_s + gap)          # np.mod, 0 where rounding gives L
        hi = np.maximum(width_left(s) - half_width, n); lo = np.minimum(half_width - width_right(s), n)
        n_end = np.clip(n + rate * horizon, lo, hi); rate_out = (n_end - n) / horizon

    (the widths as ``np.interp`` of the closed tables at ``s`` wrapped again; ``np.clip`` as numpy computes
    it: ``x`` if nan, else the larger of ``x`` and ``lo`` (``lo`` on a tie), then the same with ``hi``)."""
    for i in range(opp_rel.shape[0]):
        n = opp_rel[i, 1]
        r = opp_rel[i, 3]
        sign = 1.0 if r > 0.0 else (-1.0 if r < 0.0 else (0.0 if r == 0.0 else r))
        rate = sign * maximum(abs(r) - deadband, 0.0)
        w = wrap_at(ego_s + opp_rel[i, 0], length)
        p = w % length
        j = locate(p, knots, -1)
        hi = maximum(interp_located(j, p, knots, wl) - half_width, n)
        lo = minimum(half_width - interp_located(j, p, knots, wr), n)
        x = n + rate * horizon
        if x == x:
            x = x if x > lo else lo
        if x == x:
            x = x if x < hi else hi
        n_end[i] = x
        rate_out[i] = (x - n) / horizon


class TravelTime:
    """Travel time ``T(s)`` along a circuit's speed profile over two laps (``T(0) = 0``) [s]: the table of the
    pace-ratio prediction (:class:`OpponentPredictor`) and of the V2V plan speeds (:mod:`sofar_env.v2v`)."""

    def __init__(self, track):
        self.track = track
        samples = np.asarray(track.s, float)
        L = float(track.length)
        grid = np.concatenate([samples, samples + L, [2.0 * L]])
        v_prof = np.maximum(np.asarray(track.speed(grid), float), 0.1)
        self.s = grid
        """Arc length over two laps [m]."""
        self.t = np.concatenate([[0.0], np.cumsum(2.0 * np.diff(grid) / (v_prof[1:] + v_prof[:-1]))])
        """Travel time at :attr:`s` [s]."""

    def __call__(self, s: np.ndarray) -> np.ndarray:
        """``T`` at arc lengths ``s`` in ``[0, 2 L]`` [s]."""
        return interp(s, self.s, self.t)  # np.interp


class OpponentPredictor:
    """Opponent arc lengths over a horizon: at constant speed, or at their pace ratio.

    With ``pace_ratio`` each opponent follows ``ds/dt = rho_i v_profile(s)`` with
    ``rho_i = v_i / v_profile(s_i)``, integrated exactly through the travel time of the
    speed profile tabulated over two laps.
    """

    def __init__(self, track, pace_ratio: bool = True):
        self.track = track
        self.pace_ratio = bool(pace_ratio)
        table = TravelTime(track)
        self._s, self._t = table.s, table.t  # arc length [m] and travel time [s] over two laps
        self._knots, self._v = track.table("v")  # the speed profile's interpolation table

    def __call__(self, ego_s: float, opp_rel: np.ndarray, times: np.ndarray) -> np.ndarray:
        """(M, len(times)) arc lengths [m] at ``times`` [s] of the opponents ``opp_rel`` (rows
        (gap, n, v) relative to the ego at ``ego_s``), relative to the ego at ``ego_s``."""
        opp_rel = np.asarray(opp_rel, float).reshape(-1, 3)
        times = np.asarray(times, float)
        if opp_rel.shape[0] == 0:
            return np.zeros((0, times.size))
        if not self.pace_ratio:
            return opp_rel[:, :1] + opp_rel[:, 2:3] * times[None, :]
        return _pace_prediction(float(ego_s), opp_rel, times.reshape(-1), self._knots, self._v, self._s, self._t,
                                float(self.track.length))


@kernel
def _pace_prediction(ego_s, opp_rel, times, knots, v_closed, s_table, t_table, length):
    """:meth:`OpponentPredictor.__call__` with ``pace_ratio``: per opponent at ``s = wrap(ego_s + gap)``, the
    pace ratio ``rho = max(v, 0) / max(v_profile(s), 0.1)``, its travel time ``T(s)``, and at each time the
    arc length ``T^-1(T(s) + rho t)``, returned relative to the ego (``gap + s_pred - s``). The look-up of
    ``T^-1`` is written out as :mod:`~sofar_env.stack._lookup` describes (numpy's bits, fewer cycles)."""
    M, K = opp_rel.shape[0], times.shape[0]
    n = t_table.shape[0]
    out = np.empty((M, K))
    for i in range(M):
        gap = opp_rel[i, 0]
        s_abs = wrap_at(ego_s + gap, length)
        v_prof = interp_at(s_abs, knots, v_closed)  # s_abs is in [0, length) already
        v = opp_rel[i, 2]
        rho = (v if v >= 0.0 else 0.0) / (v_prof if v_prof >= 0.1 else 0.1)
        t0 = interp_at(s_abs, s_table, t_table)
        j = -1
        for k in range(K):
            t = t0 + rho * times[k]
            if j >= 0:  # the previous time's interval, moved forward past the knots <= t
                while j < n - 2 and t_table[j + 1] <= t:
                    j += 1
            if not (0 <= j < n - 1 and t_table[j] <= t < t_table[j + 1]):
                j = locate(t, t_table, j)
            y = np.nan
            if 0 <= j < n - 1 and t_table[j] != t:
                y = (s_table[j + 1] - s_table[j]) / (t_table[j + 1] - t_table[j]) * (t - t_table[j]) + s_table[j]
            if math.isnan(y):  # ends, knots, nan (interp_located's special cases)
                y = interp_located(j, t, t_table, s_table)
            out[i, k] = gap + (y - s_abs)
    return out


def ego_node_positions(track, ego_s: float, ego_v: float, node_t: np.ndarray, node_dt: float,
                       speed_factor: float, vehicle: VehicleParams) -> np.ndarray:
    """Ego arc length [m] at the node times ``node_t`` = 0, ``node_dt``, 2 ``node_dt``, ... [s] when
    it tracks ``speed_factor`` x the speed profile within the vehicle's acceleration limits."""
    knots, v_closed = track.table("v")
    return _ego_nodes(float(ego_s), max(float(ego_v), 0.0), np.asarray(node_t, float), float(node_dt),
                      float(speed_factor), vehicle.a_min * node_dt, vehicle.a_max * node_dt, knots, v_closed,
                      float(track.length))


@kernel
def _ego_nodes(ego_s, v0, node_t, dt, speed_factor, dv_min, dv_max, knots, v_closed, length):
    """:func:`ego_node_positions`: from the constant-speed guess ``v0 t``, two fixed-point passes of
    ``v_{k+1} = min(max(v_ref_k, v_k + dv_min), v_k + dv_max)`` (as Python's ``min``/``max`` pick) with the
    speed reference at the guessed positions, integrated by the trapezoidal rule (``s_0 = 0``). The look-up
    of the speed profile (knots nearly evenly spaced) is written out as :mod:`~sofar_env.stack._lookup`
    describes (numpy's bits, fewer cycles)."""
    N = node_t.shape[0]
    m = knots.shape[0]
    inv_spacing = (m - 1) / (knots[m - 1] - knots[0])
    s = np.empty(N)
    for k in range(N):
        s[k] = v0 * node_t[k]
    v_ref = np.empty(N)
    for _ in range(2):
        for k in range(N):
            x = wrap_mod(ego_s + s[k], length)
            j = int(x * inv_spacing) if 0.0 <= x < length else -1
            if not (0 <= j < m - 1 and knots[j] <= x < knots[j + 1]):
                j = locate(x, knots, j)
            y = np.nan
            if 0 <= j < m - 1 and knots[j] != x:
                y = (v_closed[j + 1] - v_closed[j]) / (knots[j + 1] - knots[j]) * (x - knots[j]) + v_closed[j]
            if math.isnan(y):  # ends, knots, nan (interp_located's special cases)
                y = interp_located(j, x, knots, v_closed)
            v_ref[k] = speed_factor * y
        last = v0
        acc = 0.0
        s[0] = 0.0
        for k in range(N - 1):
            lo, hi = last + dv_min, last + dv_max
            nxt = lo if lo > v_ref[k] else v_ref[k]
            if hi < nxt:
                nxt = hi
            acc = acc + 0.5 * (nxt + last) * dt
            s[k + 1] = acc
            last = nxt
    return s


def braking_positions(node_t: np.ndarray, ego_v: float, decel: float) -> np.ndarray:
    """Ego arc length [m] at the node times ``node_t`` [s] when braking at ``decel`` [m/s^2]
    from ``ego_v`` [m/s] until standstill."""
    v0 = max(ego_v, 0.0)
    tt = np.minimum(node_t, v0 / decel)
    return v0 * tt - 0.5 * decel * tt * tt
