"""Time derivative on a fixed sample grid, for the per-step hot paths.

:class:`GridGradient` evaluates ``np.gradient(f, t, axis=-1)`` (second-order central
differences inside, first-order one-sided at the ends) for a grid ``t`` fixed at
construction: the spacing coefficients are precomputed once, and the same formulas are
evaluated in the same order as numpy's, so the results are bit-identical. numpy's version
re-derives them and checks its arguments at every call, which costs more than the
arithmetic for short arrays (10 us against 30-37 us per call on the planner's 76 nodes).

Used where an env step differentiates along a fixed time grid: the closing speeds of
:mod:`sofar_env.planning.clearance` (0.6 calls per env step) and the followed cars'
speeds of :meth:`sofar_env.stack.follow.PassOrFollow.speed_cap` (0.45 calls per env step
of the ``bench/bench_env.py`` scenario).
"""

from __future__ import annotations

import numpy as np

__all__ = ["GridGradient"]


class GridGradient:
    """``np.gradient(f, t, axis=-1)`` for a fixed grid ``t`` (at least 2 increasing samples)."""

    def __init__(self, t) -> None:
        t = np.asarray(t, dtype=float).reshape(-1)
        if t.size < 2:
            raise ValueError("GridGradient needs at least 2 samples")
        dt = np.diff(t)
        self.size = int(t.size)
        # numpy uses the scalar-spacing formula when the differences are all exactly equal
        self._uniform = bool((dt == dt[0]).all())
        if self._uniform:
            self._dx = float(dt[0])
            self._two_dx = 2.0 * dt[0]
            self._dx_0 = self._dx_n = dt[0]
        else:
            dx1, dx2 = dt[:-1], dt[1:]
            self._abc = (-(dx2) / (dx1 * (dx1 + dx2)), (dx2 - dx1) / (dx1 * dx2), dx1 / (dx2 * (dx1 + dx2)))
            self._dx_0, self._dx_n = dt[0], dt[-1]

    def coefficients(self) -> tuple[bool, float, float, float, np.ndarray, np.ndarray, np.ndarray]:
        """The precomputed formula, for compiled kernels that differentiate inline:
        ``(uniform, 2 dx, dx_0, dx_n, a, b, c)``. Inside, the derivative at sample k is
        ``(f[k+1] - f[k-1]) / (2 dx)`` on a uniform grid, else ``a[k-1] f[k-1] + b[k-1] f[k] + c[k-1]
        f[k+1]`` (evaluated left to right); at the ends ``(f[1] - f[0]) / dx_0`` and ``(f[-1] - f[-2]) /
        dx_n``. ``a, b, c`` are empty on a uniform grid."""
        if self._uniform:
            empty = np.zeros(0)
            return True, float(self._two_dx), float(self._dx_0), float(self._dx_n), empty, empty, empty
        a, b, c = self._abc
        return False, 0.0, float(self._dx_0), float(self._dx_n), a, b, c

    def __call__(self, f: np.ndarray) -> np.ndarray:
        """The derivative of ``f`` (..., T) along its last axis, shape of ``f``."""
        f = np.asarray(f, dtype=float)
        if f.shape[-1] != self.size:
            raise ValueError(f"last axis must have {self.size} samples, got shape {f.shape}")
        out = np.empty_like(f)
        if self.size > 2:
            if self._uniform:
                out[..., 1:-1] = (f[..., 2:] - f[..., :-2]) / self._two_dx
            else:
                a, b, c = self._abc
                out[..., 1:-1] = a * f[..., :-2] + b * f[..., 1:-1] + c * f[..., 2:]
        out[..., 0] = (f[..., 1] - f[..., 0]) / self._dx_0
        out[..., -1] = (f[..., -1] - f[..., -2]) / self._dx_n
        return out
