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

from .._interp import interp
from ..vehicle import VehicleParams

__all__ = ["TrackEdges"]


class TrackEdges:
    """Lateral bounds (n_min, n_max) of the planners along the track [m]."""

    def __init__(self, track, vehicle: VehicleParams, footprint_aware: bool = True):
        self.track = track
        self.footprint_aware = bool(footprint_aware)
        self._reach = max(vehicle.cg_to_front, vehicle.cg_to_rear)
        # footprint samples along the track, from the rear end to the front end
        self._offsets = np.linspace(-vehicle.cg_to_rear, vehicle.cg_to_front, 5)

    def __call__(self, s_abs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(n_min, n_max) at arc lengths ``s_abs`` [m]: with ``footprint_aware`` the narrowest
        within the car's length around each point, else the edges there."""
        s_abs = np.asarray(s_abs, float)
        if not self.footprint_aware:
            return (-np.asarray(self.track.width_right(s_abs), float),
                    np.asarray(self.track.width_left(s_abs), float))
        pts = s_abs[:, None] + self._offsets[None, :]
        flat = pts.ravel()
        wr = np.minimum.reduce(np.asarray(self.track.width_right(flat), float).reshape(pts.shape), axis=1)
        wl = np.minimum.reduce(np.asarray(self.track.width_left(flat), float).reshape(pts.shape), axis=1)
        return -wr, wl

    def for_mpc(self, s_abs: np.ndarray, x_prev: np.ndarray | None, t: np.ndarray,
                shift: float) -> tuple[np.ndarray, np.ndarray]:
        """The MPC's bounds at ``s_abs`` [m]: :meth:`__call__`, with ``footprint_aware`` tightened on
        both sides by how far the car's ends swing out at the heading error along the horizon.

        The heading error is guessed from the previous MPC prediction ``x_prev`` (rows
        (s, n, e, ...) at the times ``t`` [s]; None: no tightening) shifted by ``shift`` [s],
        one control period.
        """
        n_min, n_max = self(s_abs)
        if self.footprint_aware and x_prev is not None:
            e_abs = np.abs(interp(t + shift, t, x_prev[:, 2]))  # np.interp
            swing = self._reach * np.sin(np.minimum(e_abs, 0.5 * math.pi))
            n_min = n_min + swing
            n_max = n_max - swing
        return n_min, n_max
