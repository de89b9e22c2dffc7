"""The periodic C2 cubic spline through the raceline samples.

:class:`PeriodicCurve` is the closed planar curve both :class:`~sofar_env.tracks.Track`
(positions, heading, normal and the Frenet projection) and the builder (heading and
curvature of the stored raceline) evaluate, vectorised on arrays and on Python floats;
and the compiled loops of the track's periodic arc-length algebra and poses
(:func:`floor_mod`, :func:`gap_in_place`, :func:`lerp_wrapped`, :func:`tangents_into`).
"""

from __future__ import annotations

import bisect
import math

import numpy as np
from scipy.interpolate import CubicSpline

from .._interp import locate
from .._jit import kernel

__all__ = ["PeriodicCurve", "floor_mod", "gap_in_place", "lerp_wrapped", "tangents_into"]


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


# compiled loops of the track's periodic arc-length algebra: one call instead of five or three numpy
# calls (or a dozen scalar calls) on a few elements, the same operations in the same order, so the same
# bits (see sofar_env._jit). They fill arrays given to them: a kernel returning a new array pays ~1 us
# to box it.
@kernel
def floor_mod(x, length):
    """``x % length`` for ``length > 0`` (Python's and numpy's floor modulo, to the bit), with shortcuts for
    ``x`` within one period of [0, length), where ``fmod`` is exact: ``x``, ``x - length`` (exact) or ``x +
    length`` (the one rounding the floor modulo also does)."""
    if 0.0 < x < length:
        return x
    if length <= x < 2.0 * length:
        return x - length
    if -length < x < 0.0:
        return x + length
    return x % length


@kernel
def gap_in_place(d, half, length):
    """``d <- wrap(d + half) - half`` for a 1-D float array ``d`` of differences ``s_a - s_b`` [m], in
    place: the signed periodic gaps in [-half, half) of :meth:`Track.gap` (``half = length / 2``),
    where wrap is ``np.mod`` into [0, length) with 0 where rounding gives ``length``."""
    for i in range(d.shape[0]):
        r = floor_mod(d[i] + half, length)
        if r >= length:
            r = 0.0
        d[i] = r - half


@kernel
def lerp_wrapped(s, length, knots, table):
    """``Track._interp_scalar`` inside a kernel: the closed ``table`` at the scalar ``s`` [m] wrapped into
    [0, length) (0 where rounding gives ``length``), as ``f_i + w (f_{i+1} - f_i)`` with ``w = (s - k_i) /
    (k_{i+1} - k_i)`` on the piece ``i`` holding ``s`` (not numpy's formula; the same bits as the Python
    method)."""
    s = floor_mod(s, length)
    if s >= length:
        s = 0.0
    i = min(max(locate(s, knots, -1), 0), knots.shape[0] - 2)
    k0 = knots[i]
    w = (s - k0) / (knots[i + 1] - k0)
    return table[i] + w * (table[i + 1] - table[i])


@kernel
def tangents_into(s, knots, coefs, last, length, out):
    """Rows ``(x, y, x', y', atan2(y', x'))`` of ``out``: the spline with piece coefficients ``coefs`` (K, 8) at
    each ``s[i]`` wrapped into [0, length) (0 where rounding gives ``length``), on the piece of the last knot
    <= s (clipped to ``[0, last]``): :meth:`PeriodicCurve.tangent_scalar` and the heading of ``Track.pose``."""
    for k in range(s.shape[0]):
        p = s[k] % length
        if p >= length:
            p = 0.0
        i = min(max(locate(p, knots, -1), 0), last)
        t = p - knots[i]
        a, b, c, d, e, f, g, h = coefs[i, 0], coefs[i, 1], coefs[i, 2], coefs[i, 3], coefs[i, 4], coefs[i, 5], \
            coefs[i, 6], coefs[i, 7]
        dx = (3.0 * a * t + 2.0 * b) * t + c
        dy = (3.0 * e * t + 2.0 * f) * t + g
        out[k, 0] = ((a * t + b) * t + c) * t + d
        out[k, 1] = ((e * t + f) * t + g) * t + h
        out[k, 2] = dx
        out[k, 3] = dy
        out[k, 4] = math.atan2(dy, dx)
