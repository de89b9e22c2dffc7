"""Lateral offsets of the car's ends that the MPC's end rows bound (``MPCConfig.track_rows``).

With ``track_rows = "ends"`` the four track rows of a stage bound, against the upper (left) and the
lower (right) edge, the offsets of the front and of the rear end of the car::

    front: n + g_up(e) <= n_max,   n + g_lo(e) >= n_min       (g_up = g_lo = l sin e)
    rear:  n - l sin e <= n_max,   n - l sin e >= n_min

with ``l = max(l_f, l_r)`` and ``e`` the heading error (ignoring the track's curvature over the car's
length, which the footprint-aware edges cover).

``"recoverable"`` also keeps room for turning back: a car turned towards an edge by more than
``e*`` cannot drive forward without its front end first moving further out, even at full steering
lock, and with no reverse gear such a car standing near the edge is stuck (the *stall* of the
interactive world's failures). Its front rows then bound the largest offset the front end reaches
while the car turns back to the track's direction at full lock (steering angle ``delta_max``, path
curvature ``k = cos(beta) tan(delta_max) / L``, course ``e + beta`` with the slip angle ``beta`` of
that lock, turning away from the edge)::

    g_up(e) = l sin e                                          for e <= e*
    g_up(e) = l sin e* + (cos(e* + beta) - cos(e + beta)) / k   for e > e*      (beta < 0 here)
    tan e* = (l k - sin beta) / cos beta                                          (g_up' continuous)
    g_lo(e) = -g_up(-e)

The second branch is the front end's offset at ``e*``, where it stops moving out, reached from ``e``
along the turn: ``n`` changes by ``(cos(e* + beta) - cos(e + beta)) / k`` on the way. With the AV-21's
geometry ``e*`` = 0.31 rad: turns of less than that, every heading error at racing speed, are bounded
exactly as with ``"ends"``. It assumes the lock is reached at once, which at the low speeds where such
heading errors occur (steering rate 0.35 rad/s) costs little distance.

Pure math: no state, numpy for the RTI, CasADi expressions for the IPOPT reference.
"""

from __future__ import annotations

import math

import numpy as np

from ...vehicle import VehicleParams

__all__ = ["EndOffsets"]


class EndOffsets:
    """The four end offsets of the track rows and their slopes in ``e`` (module docstring)."""

    def __init__(self, vehicle: VehicleParams, recoverable: bool):
        self.reach = max(vehicle.cg_to_front, vehicle.cg_to_rear)
        """l [m]."""
        self.recoverable = bool(recoverable)
        # the turn back to the track's direction at full lock, for a car turned to the left (e > 0)
        delta = -vehicle.steer_max
        self.beta = math.atan(vehicle.lr / vehicle.wheelbase * math.tan(delta))
        """Slip angle of that turn [rad] (< 0)."""
        self.curvature = math.cos(self.beta) * math.tan(vehicle.steer_max) / vehicle.wheelbase
        """k, curvature of the path of the reference point at full lock [1/m]."""
        self.e_star = math.atan2(self.reach * self.curvature - math.sin(self.beta), math.cos(self.beta))
        """e* [rad]: from this heading error on the front end moves out while turning back."""
        self._top = self.reach * math.sin(self.e_star)

    @classmethod
    def for_rows(cls, track_rows: str, vehicle: VehicleParams) -> EndOffsets | None:
        """The offsets of ``MPCConfig.track_rows``: None for ``"reference"`` (the rows bound the reference
        point), else those of ``"ends"`` or ``"recoverable"``."""
        return None if track_rows == "reference" else cls(vehicle, recoverable=track_rows == "recoverable")

    def _front(self, e: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``g_up(e)`` and its slope."""
        g = self.reach * np.sin(e)
        dg = self.reach * np.cos(e)
        if self.recoverable:
            out = e > self.e_star
            if out.any():
                eb = e[out] + self.beta
                g[out] = self._top + (math.cos(self.e_star + self.beta) - np.cos(eb)) / self.curvature
                dg[out] = np.sin(eb) / self.curvature
        return g, dg

    def __call__(self, e: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(values, slopes)``, each (4, len(e)), of the rows [front up, front low, rear up, rear low]
        at the heading errors ``e`` [rad]: ``g_up, g_lo, -l sin e, -l sin e`` and their derivatives."""
        e = np.asarray(e, dtype=float)
        g_up, dg_up = self._front(e)
        g_neg, dg_neg = self._front(-e)
        rear, drear = -self.reach * np.sin(e), -self.reach * np.cos(e)
        return np.stack([g_up, -g_neg, rear, rear]), np.stack([dg_up, dg_neg, drear, drear])

    def symbolic(self, e):
        """The four offsets as CasADi expressions of the symbol ``e`` (for the IPOPT reference)."""
        import casadi as ca

        def front(x):
            g = self.reach * ca.sin(x)
            if not self.recoverable:
                return g
            far = self._top + (math.cos(self.e_star + self.beta) - ca.cos(x + self.beta)) / self.curvature
            return ca.if_else(x > self.e_star, far, g)

        rear = -self.reach * ca.sin(e)
        return [front(e), -front(-e), rear, rear]
