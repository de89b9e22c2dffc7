"""The periodic C2 cubic spline through the raceline samples.

:class:`PeriodicCurve` is the closed planar curve both :class:`~sofar_env.tracks.Track`
(positions, heading, normal and the Frenet projection) and the builder (heading and
curvature of the stored raceline) evaluate, vectorised on arrays and on Python floats.
"""

from __future__ import annotations

import bisect

import numpy as np
from scipy.interpolate import CubicSpline

__all__ = ["PeriodicCurve"]


class PeriodicCurve:
    """Closed planar curve: periodic C2 cubic spline through (s_k, x_k, y_k).

    ``s`` must start at 0, increase strictly and stay below ``length``; the
    curve closes from the last sample back to the first at s = length.
    """

    def __init__(self, s: np.ndarray, xy: np.ndarray, length: float):
        s = np.asarray(s, dtype=float)
        xy = np.asarray(xy, dtype=float)
        self.length = float(length)
        self.knots = np.append(s, self.length)
        sx = CubicSpline(self.knots, np.append(xy[:, 0], xy[0, 0]), bc_type="periodic")
        sy = CubicSpline(self.knots, np.append(xy[:, 1], xy[0, 1]), bc_type="periodic")
        self.cx = np.ascontiguousarray(sx.c)  # (4, K): c0 t^3 + c1 t^2 + c2 t + c3
        self.cy = np.ascontiguousarray(sy.c)
        self._knots_list = self.knots.tolist()
        self._coef_list = np.vstack([self.cx, self.cy]).T.tolist()  # K rows of 8 floats
        self._last = len(s) - 1

    # vectorised -------------------------------------------------------------
    def wrap(self, s: np.ndarray) -> np.ndarray:
        r = np.mod(s, self.length)
        return np.where(r >= self.length, 0.0, r)

    def locate(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Segment index and local parameter for wrapped ``s``."""
        i = np.searchsorted(self.knots, s, side="right") - 1
        i = np.clip(i, 0, self._last)
        return i, s - self.knots[i]

    def eval(self, s: np.ndarray, order: int = 1) -> list[np.ndarray]:
        """[x, y, x', y'(, x'', y'')] at wrapped ``s`` (order 0, 1 or 2)."""
        i, t = self.locate(s)
        out = []
        for c in (self.cx, self.cy):
            a, b, cc, d = c[0, i], c[1, i], c[2, i], c[3, i]
            out.append(((a * t + b) * t + cc) * t + d)
        if order >= 1:
            for c in (self.cx, self.cy):
                a, b, cc = c[0, i], c[1, i], c[2, i]
                out.append((3.0 * a * t + 2.0 * b) * t + cc)
        if order >= 2:
            for c in (self.cx, self.cy):
                out.append(6.0 * c[0, i] * t + 2.0 * c[1, i])
        return out

    def curvature(self, s: np.ndarray) -> np.ndarray:
        _, _, dx, dy, ddx, ddy = self.eval(s, order=2)
        return (dx * ddy - dy * ddx) / np.power(dx * dx + dy * dy, 1.5)

    # scalar -----------------------------------------------------------------
    def wrap_scalar(self, s: float) -> float:
        r = s % self.length
        return 0.0 if r >= self.length else r

    def _segment(self, s: float) -> tuple[float, tuple]:
        """(t, coefficients) of the spline piece holding the wrapped scalar ``s``, t = s - its knot."""
        i = bisect.bisect_right(self._knots_list, s) - 1
        if i > self._last:
            i = self._last
        elif i < 0:
            i = 0
        return s - self._knots_list[i], self._coef_list[i]

    @staticmethod
    def _position_tangent(t: float, coef: tuple) -> tuple[float, float, float, float]:
        """(x, y, x', y') of the cubic piece with coefficients ``coef`` at local parameter ``t``."""
        a, b, c, d, e, f, g, h = coef
        return (
            ((a * t + b) * t + c) * t + d,
            ((e * t + f) * t + g) * t + h,
            (3.0 * a * t + 2.0 * b) * t + c,
            (3.0 * e * t + 2.0 * f) * t + g,
        )

    def tangent_scalar(self, s: float) -> tuple[float, float, float, float]:
        """(x, y, x', y') at a wrapped scalar ``s`` (the first four values of :meth:`eval_scalar`)."""
        return self._position_tangent(*self._segment(s))

    def eval_scalar(self, s: float) -> tuple[float, float, float, float, float, float]:
        """(x, y, x', y', x'', y'') at a wrapped scalar ``s``."""
        t, coef = self._segment(s)
        a, b, _, _, e, f, _, _ = coef
        return self._position_tangent(t, coef) + (6.0 * a * t + 2.0 * b, 6.0 * e * t + 2.0 * f)
