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

``"recoverable-curved"`` also counts the track's curvature ``kappa`` at each stage. In a corner the track's
direction turns while the car turns back (``e' = v k - kappa s'``): a car turned towards the outside edge turns
back relative to the track only at ``k - |kappa|`` and drifts much further out (from 0.9 rad in a corner of 22 m
radius about 8 m instead of 4). Its rows use the formulas above with the curvature ``k - max(kappa, 0)`` for the
right edge (a left-hand corner, ``kappa > 0``, turns away from a car turned to the right) and ``k -
max(-kappa, 0)`` for the left edge, at least :data:`MIN_TURN_BACK_SHARE` of ``k``; a corner that turns the
track towards the car is not counted (``s' <= v`` and ``1 - kappa n >= 1`` outside: the rows are conservative).

Pure math: no state, numpy for the RTI, CasADi expressions for the IPOPT reference.
"""

from __future__ import annotations

import math

import numpy as np

from ...vehicle import VehicleParams

__all__ = ["EndOffsets", "MIN_TURN_BACK_SHARE"]

MIN_TURN_BACK_SHARE = 0.25
"""``"recoverable-curved"``: the turn-back curvature relative to the track is at least this share of the lock's
``k`` (a corner tighter than ``1 / ((1 - share) k)``, 15.6 m for the AV-21, counts as that one), so that the
offsets stay finite; the rows are soft."""


class EndOffsets:
    """The four end offsets of the track rows and their slopes in ``e`` (module docstring)."""

    def __init__(self, vehicle: VehicleParams, recoverable: bool, curved: bool = False):
        self.reach = max(vehicle.cg_to_front, vehicle.cg_to_rear)
        """l [m]."""
        self.recoverable = bool(recoverable)
        self.curved = bool(curved) and self.recoverable
        """Whether the turn back counts the track's curvature (``"recoverable-curved"``)."""
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
        point), else those of ``"ends"``, ``"recoverable"`` or ``"recoverable-curved"``."""
        if track_rows == "reference":
            return None
        return cls(vehicle, recoverable=track_rows.startswith("recoverable"), curved=track_rows == "recoverable-curved")

    def turn_back_curvatures(self, kappa: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
        """The turn-back curvature relative to the track for the left (up) and the right (low) edge at the track
        curvatures ``kappa`` [1/m] (module docstring); both ``k`` where the rows do not count the curvature."""
        kappa = np.asarray(kappa, dtype=float)
        k = self.curvature
        if not self.curved:
            return np.full(kappa.shape, k), np.full(kappa.shape, k)
        floor = MIN_TURN_BACK_SHARE * k
        return np.maximum(k - np.maximum(-kappa, 0.0), floor), np.maximum(k - np.maximum(kappa, 0.0), floor)

    def _front(self, e: np.ndarray, k: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """``g_up(e)`` and its slope; ``k``: the turn-back curvature of each entry (default: the lock's)."""
        g = self.reach * np.sin(e)
        dg = self.reach * np.cos(e)
        if not self.recoverable:
            return g, dg
        if k is None:  # the lock's curvature: the constants of __init__
            out = e > self.e_star
            if out.any():
                eb = e[out] + self.beta
                g[out] = self._top + (math.cos(self.e_star + self.beta) - np.cos(eb)) / self.curvature
                dg[out] = np.sin(eb) / self.curvature
            return g, dg
        e_star = np.arctan2(self.reach * k - math.sin(self.beta), math.cos(self.beta))
        out = e > e_star
        if out.any():
            eb, k_out, star = e[out] + self.beta, k[out], e_star[out]
            g[out] = self.reach * np.sin(star) + (np.cos(star + self.beta) - np.cos(eb)) / k_out
            dg[out] = np.sin(eb) / k_out
        return g, dg

    def __call__(self, e: np.ndarray, kappa: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """``(values, slopes)``, each (4, len(e)), of the rows [front up, front low, rear up, rear low]
        at the heading errors ``e`` [rad]: ``g_up, g_lo, -l sin e, -l sin e`` and their derivatives.
        ``kappa``: the track's curvature at each entry [1/m], used by the ``curved`` rows (none: a straight)."""
        e = np.asarray(e, dtype=float)
        k_up = k_lo = None
        if self.curved and kappa is not None:
            k_up, k_lo = self.turn_back_curvatures(np.broadcast_to(np.asarray(kappa, dtype=float), e.shape))
        g_up, dg_up = self._front(e, k_up)
        g_neg, dg_neg = self._front(-e, k_lo)
        rear, drear = -self.reach * np.sin(e), -self.reach * np.cos(e)
        return np.stack([g_up, -g_neg, rear, rear]), np.stack([dg_up, dg_neg, drear, drear])

    def symbolic(self, e, kappa=0.0):
        """The four offsets as CasADi expressions of the symbol ``e`` (for the IPOPT reference); ``kappa``: the
        track's curvature (a symbol or a number; used by the ``curved`` rows)."""
        import casadi as ca

        k, beta = self.curvature, self.beta

        def front(x, k_turn):
            g = self.reach * ca.sin(x)
            if not self.recoverable:
                return g
            e_star = ca.atan2(self.reach * k_turn - math.sin(beta), math.cos(beta))
            far = self.reach * ca.sin(e_star) + (ca.cos(e_star + beta) - ca.cos(x + beta)) / k_turn
            return ca.if_else(x > e_star, far, g)

        k_up = k_lo = k
        if self.curved:
            floor = MIN_TURN_BACK_SHARE * k
            k_up = ca.fmax(k - ca.fmax(-kappa, 0.0), floor)
            k_lo = ca.fmax(k - ca.fmax(kappa, 0.0), floor)
        rear = -self.reach * ca.sin(e)
        return [front(e, k_up), -front(-e, k_lo), rear, rear]
