"""The lateral track bounds given to the planners (footprint-aware track edges).

Leaving the track is judged on the footprint's corners, while the MPC keeps its
reference point ``track_margin`` from the edge. With ``footprint_aware`` (an addition
to the paper's algorithm):

* the edges given to the planners are the narrowest within the car's length around
  each predicted position (edges converge on the raceline by up to 0.5 m per metre in
  chicanes), and
* the MPC's are further tightened by ``max(l_f, l_r) |sin e|`` with the heading error
  ``e`` of the previous prediction: how far a corner swings out when the car is not
  aligned with the track.

Without it the bounds are the track's edges at the reference point, as in the paper.
"""

from __future__ import annotations

import math

import numpy as np

from .._interp import interp, interp_located, locate
from .._jit import kernel, minimum
from ..vehicle import VehicleParams
from ._lookup import slopes, wrap_mod

__all__ = ["TrackEdges"]


class TrackEdges:
    """Lateral bounds (n_min, n_max) of the planners along the track [m]."""

    def __init__(self, track, vehicle: VehicleParams, footprint_aware: bool = True):
        self.track = track
        self.footprint_aware = bool(footprint_aware)
        self._reach = max(vehicle.cg_to_front, vehicle.cg_to_rear)
        # footprint samples along the track, from the rear end to the front end
        self._offsets = np.linspace(-vehicle.cg_to_rear, vehicle.cg_to_front, 5)
        self._knots, self._wl = track.table("wl")
        self._wr = track.table("wr")[1]
        self._slope_l = slopes(self._knots, self._wl)  # the interpolation's slopes, computed once
        self._slope_r = slopes(self._knots, self._wr)
        self._inv_spacing = (len(self._knots) - 1) / float(self._knots[-1] - self._knots[0])  # knots ~ j h
        self._length = float(track.length)

    def __call__(self, s_abs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(n_min, n_max) at arc lengths ``s_abs`` [m]: with ``footprint_aware`` the narrowest
        within the car's length around each point, else the edges there."""
        s_abs = np.asarray(s_abs, float)
        if not self.footprint_aware:
            return (-np.asarray(self.track.width_right(s_abs), float),
                    np.asarray(self.track.width_left(s_abs), float))
        return _narrowest_edges(s_abs.reshape(-1), self._offsets, self._knots, self._wl, self._wr, self._slope_l,
                                self._slope_r, self._inv_spacing, self._length)

    def kernel_data(self) -> tuple:
        """What a compiled caller needs to compute :meth:`__call__` itself (:mod:`~sofar_env.stack.stage`):
        ``(footprint_aware, offsets, knots, wl, wr, slope_l, slope_r, inv_spacing)``."""
        return (self.footprint_aware, self._offsets, self._knots, self._wl, self._wr, self._slope_l, self._slope_r,
                self._inv_spacing)

    def for_mpc(self, s_abs: np.ndarray, x_prev: np.ndarray | None, t: np.ndarray,
                shift: float, edge_relative: bool = False,
                edges: tuple[np.ndarray, np.ndarray] | None = None) -> tuple[np.ndarray, np.ndarray]:
        """The MPC's bounds at ``s_abs`` [m]: :meth:`__call__`, with ``footprint_aware`` tightened on
        both sides by how far the car's ends swing out at the heading error along the horizon.

        The heading error is guessed from the previous MPC prediction ``x_prev`` (rows
        (s, n, e, ...) at the times ``t`` [s]; None: no tightening) shifted by ``shift`` [s],
        one control period.

        With ``edge_relative`` the swing is measured against each edge's direction: an end of the car
        ``l`` ahead of (behind) the reference point is ``l sin e`` to the side, where the edge, of slope
        ``k`` along the track, has moved by ``l k``, so the reference point must keep ``l |sin e - k|``
        (``l = max(l_f, l_r)``) from the edge at its own position. The narrowest edge within the
        car's length already takes ``l |k|`` off, so only ``l max(0, |sin e - k| - |k|)`` is taken
        off it: the same as ``l |sin e|`` along parallel edges, less for a car that follows an edge
        converging on the reference line (a chicane, where the raceline crosses the track) and has a
        heading error to the reference line while its ends stay clear of that edge.

        ``edges``: ``self(s_abs)`` when the caller has computed it already.
        """
        n_min, n_max = self(s_abs) if edges is None else edges
        if self.footprint_aware and x_prev is not None:
            e = interp(t + shift, t, x_prev[:, 2])  # np.interp
            if edge_relative:
                h = 0.5  # [m] half-step of the edges' slope
                lo_ahead, hi_ahead = self(s_abs + h)
                lo_behind, hi_behind = self(s_abs - h)
                sin_e = np.sin(np.clip(e, -0.5 * math.pi, 0.5 * math.pi))
                swing = []
                for slope in ((lo_ahead - lo_behind) / (2.0 * h), (hi_ahead - hi_behind) / (2.0 * h)):
                    swing.append(self._reach * np.maximum(np.abs(sin_e - slope) - np.abs(slope), 0.0))
                return n_min + swing[0], n_max - swing[1]
            swing = self._reach * np.sin(np.minimum(np.abs(e), 0.5 * math.pi))
            n_min = n_min + swing
            n_max = n_max - swing
        return n_min, n_max


@kernel
def _narrowest_edges(s_abs, offsets, knots, wl, wr, slope_l, slope_r, inv_spacing, length):
    """(-min wr, min wl) over the points ``s_abs[k] + offsets`` of each ``s_abs[k]``, the widths interpolated
    as the track interpolates them (:meth:`~sofar_env.tracks.Track.table`; both columns share the knots,
    nearly evenly spaced at ``1 / inv_spacing``; ``slope_l``, ``slope_r``: their slopes). The look-up is
    written out as :mod:`~sofar_env.stack._lookup` describes (numpy's bits, fewer cycles)."""
    n = s_abs.shape[0]
    m = knots.shape[0]
    n_min = np.empty(n)
    n_max = np.empty(n)
    for k in range(n):
        lo = hi = np.inf
        for i in range(offsets.shape[0]):
            s = wrap_mod(s_abs[k] + offsets[i], length)
            j = int(s * inv_spacing) if 0.0 <= s < length else -1
            if not (0 <= j < m - 1 and knots[j] <= s < knots[j + 1]):
                j = locate(s, knots, j)
            a = b = np.nan
            if 0 <= j < m - 1 and knots[j] != s:
                d = s - knots[j]
                a = slope_r[j] * d + wr[j]
                b = slope_l[j] * d + wl[j]
            if math.isnan(a) or math.isnan(b):  # ends, knots, nan (interp_located's special cases)
                a = interp_located(j, s, knots, wr)
                b = interp_located(j, s, knots, wl)
            lo = minimum(lo, a)
            hi = minimum(hi, b)
        n_min[k] = -lo
        n_max[k] = hi
    return n_min, n_max
