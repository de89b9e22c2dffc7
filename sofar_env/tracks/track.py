"""The :class:`Track` class: a closed circuit with a Frenet frame along its raceline.

:meth:`Track.load` reads a circuit folder (the format is in :mod:`.format`).

Conventions: the Frenet frame follows the raceline, s is the arc length in
[0, L) and periodic, n > 0 to the left of the driving direction, curvature
kappa > 0 in left turns, heading psi measured from the x axis.  Positions along
the raceline are interpolated by a periodic C2 cubic spline in s; curvature,
widths and speed are interpolated linearly (periodically) between samples.
"""

from __future__ import annotations

import bisect
import math
import os
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from .._interp import interp, locate
from .._jit import kernel
from .curve import PeriodicCurve, gap_in_place, tangents_into
from .format import (
    EDGE_COLUMNS,
    LEFT_EDGE_FILE,
    META_FILE,
    RACELINE_COLUMNS,
    RACELINE_FILE,
    RIGHT_EDGE_FILE,
    TrackFormatError,
    check_raceline_samples,
    describe,
    parse_csv_table,
    parse_meta,
    read_text,
)
from .names import ALIASES, unknown_name_error

__all__ = ["Track"]

_MIN_RACELINE_ROWS = 16
_MIN_EDGE_ROWS = 8
_NEWTON_MAX_ITER = 25
_NEWTON_TOL = 1e-10  # [m] step size at which the projection is converged
_HINT_WINDOW = 40.0  # [m] half width of the local search window around s_hint


def _as_scalar(value: Any) -> float | None:
    """Python float when ``value`` is a scalar, else None."""
    kind = type(value)
    if kind is float:  # the common case first: the per-step callers pass Python floats
        return value
    if kind is np.ndarray:
        return float(value) if value.ndim == 0 else None
    if isinstance(value, (float, int)):
        return float(value)
    return float(value) if np.ndim(value) == 0 else None


# ------------------------------------------------------------------------ Track


class Track:
    """A closed circuit with a Frenet frame along its raceline.

    Attributes:
        name: circuit name.
        length: closed raceline length L [m].
        s: arc length of the raceline samples, shape (K,), s[0] = 0, s[-1] < L [m].
        xy: raceline samples, shape (K, 2) [m].
        psi, kappa: heading [rad] and signed curvature [1/m] at the samples.
        w_left, w_right: distance from the raceline to the left / right edge
            along the normal at the samples [m] (both positive on track).
        v: speed profile at the samples [m/s].
        left_edge, right_edge: closed edge polylines, shapes (M, 2) [m].
        max_speed: highest speed of the speed profile [m/s].
        meta: the parsed ``meta.json`` (builder parameters, provenance, ...).
    """

    def __init__(
        self,
        name: str,
        length: float,
        raceline: np.ndarray,
        left_edge: np.ndarray,
        right_edge: np.ndarray,
        meta: dict | None = None,
        source: str = "<memory>",
    ):
        raceline = np.asarray(raceline, dtype=float)
        where = f"{source}/{RACELINE_FILE}" if source != "<memory>" else "raceline"
        if raceline.ndim != 2 or raceline.shape[1] != len(RACELINE_COLUMNS):
            raise TrackFormatError(f"{where}: expected {len(RACELINE_COLUMNS)} columns")
        if len(raceline) < _MIN_RACELINE_ROWS:
            raise TrackFormatError(f"{where}: at least {_MIN_RACELINE_ROWS} rows required")
        length = float(length)
        s = raceline[:, 0]
        if abs(s[0]) > 1e-9:
            raise TrackFormatError(f"{where}: s must start at 0, got {s[0]}")
        ds = np.diff(s)
        if np.any(ds <= 0.0):
            k = int(np.argmax(ds <= 0.0))
            raise TrackFormatError(f"{where}: s is not strictly increasing at line {k + 3}")
        if not s[-1] < length:
            raise TrackFormatError(
                f"{where}: last s {s[-1]} is not below the lap length {length} from {META_FILE}"
            )
        for edge, label in ((left_edge, LEFT_EDGE_FILE), (right_edge, RIGHT_EDGE_FILE)):
            edge = np.asarray(edge)
            if edge.ndim != 2 or edge.shape[1] != 2 or len(edge) < _MIN_EDGE_ROWS:
                raise TrackFormatError(f"{source}/{label}: expected at least {_MIN_EDGE_ROWS} rows of x, y")

        self.name = str(name)
        self.length = length
        self.meta = dict(meta or {})
        self.s = np.ascontiguousarray(s)
        self.xy = np.ascontiguousarray(raceline[:, 1:3])
        self.psi = raceline[:, 3].copy()
        self.kappa = raceline[:, 4].copy()
        self.w_left = raceline[:, 5].copy()
        self.w_right = raceline[:, 6].copy()
        self.v = raceline[:, 7].copy()
        self.left_edge = np.ascontiguousarray(left_edge, dtype=float)
        self.right_edge = np.ascontiguousarray(right_edge, dtype=float)
        self.max_speed = float(self.v.max())
        for arr in (self.s, self.xy, self.psi, self.kappa, self.w_left, self.w_right, self.v):
            arr.setflags(write=False)

        self._curve = PeriodicCurve(self.s, self.xy, length)
        self._tree = cKDTree(self.xy)
        self._K = len(self.s)
        self._spacing = length / self._K
        self._max_step = 2.0 * float(max(ds.max(), length - s[-1]))
        self._hint_half = max(2, int(math.ceil(_HINT_WINDOW / self._spacing)))
        self._hint_offsets = np.arange(-self._hint_half, self._hint_half + 1)
        # periodic linear interpolation tables (closed with the first sample)
        self._knots = self._curve.knots
        self._knots_list = self._curve._knots_list
        self._coefs = np.ascontiguousarray(np.vstack([self._curve.cx, self._curve.cy]).T)  # (K, 8) spline pieces
        self._tables = {}
        for key, col in (("kappa", self.kappa), ("wl", self.w_left), ("wr", self.w_right), ("v", self.v)):
            closed = np.append(col, col[0])
            self._tables[key] = (closed, closed.tolist())
        self._table_views = {}  # read-only (knots, values) views for table()
        for key, (closed, _) in self._tables.items():
            views = (self._knots.view(), closed.view())
            for v in views:
                v.setflags(write=False)
            self._table_views[key] = views

    # ---------------------------------------------------------------- loading
    @classmethod
    def load(cls, name_or_path: str | os.PathLike) -> "Track":
        """Load a shipped circuit by name/alias, or a circuit folder by path."""
        if not isinstance(name_or_path, os.PathLike):
            key = str(name_or_path).strip().lower()
            if key in ALIASES:
                canonical = ALIASES[key]
                folder = resources.files("sofar_env.track_data").joinpath(canonical)
                return cls._load_folder(folder, str(folder))
        text = os.fspath(name_or_path)
        path = Path(text).expanduser()
        looks_like_path = isinstance(name_or_path, os.PathLike) or os.sep in text or (
            os.altsep is not None and os.altsep in text
        )
        if path.is_dir():
            return cls._load_folder(path, str(path))
        if looks_like_path or path.exists():
            raise TrackFormatError(f"{path}: no such circuit folder")
        raise unknown_name_error(text)

    @classmethod
    def _load_folder(cls, folder: Any, label: str) -> "Track":
        meta = parse_meta(read_text(folder, META_FILE), describe(folder, META_FILE))
        raceline = parse_csv_table(
            read_text(folder, RACELINE_FILE), describe(folder, RACELINE_FILE), RACELINE_COLUMNS, _MIN_RACELINE_ROWS
        )
        left = parse_csv_table(
            read_text(folder, LEFT_EDGE_FILE), describe(folder, LEFT_EDGE_FILE), EDGE_COLUMNS, _MIN_EDGE_ROWS
        )
        right = parse_csv_table(
            read_text(folder, RIGHT_EDGE_FILE), describe(folder, RIGHT_EDGE_FILE), EDGE_COLUMNS, _MIN_EDGE_ROWS
        )
        check_raceline_samples(
            raceline, float(meta["length_m"]), describe(folder, RACELINE_FILE), describe(folder, META_FILE)
        )
        return cls(meta["name"], meta["length_m"], raceline, left, right, meta, source=label)

    def __repr__(self) -> str:
        return f"Track(name={self.name!r}, length={self.length:.2f} m, samples={self._K})"

    # ------------------------------------------------------------- s algebra
    def wrap(self, s):
        """Arc length wrapped into [0, L)."""
        if type(s) is float:
            r = s % self.length
            return 0.0 if r >= self.length else r
        sc = _as_scalar(s)
        if sc is not None:
            return self._curve.wrap_scalar(sc)
        return self._curve.wrap(np.asarray(s, dtype=float))

    def gap(self, s_a, s_b):
        """Signed periodic difference s_a - s_b in [-L/2, L/2)."""
        if type(s_a) is float and type(s_b) is float:
            half = 0.5 * self.length
            r = (s_a - s_b + half) % self.length
            return (0.0 if r >= self.length else r) - half
        a, b = _as_scalar(s_a), _as_scalar(s_b)
        if a is not None and b is not None:
            return self._gap_scalar(a, b)
        d = np.subtract(s_a, s_b, dtype=float)  # a new array (one operand is not a scalar)
        gap_in_place(d.reshape(-1), 0.5 * self.length, self.length)  # wrap(d + L/2) - L/2
        return d

    def _gap_scalar(self, a: float, b: float) -> float:
        """:meth:`gap` of two Python floats."""
        half = 0.5 * self.length
        r = (a - b + half) % self.length
        return (0.0 if r >= self.length else r) - half

    # ---------------------------------------------------- sampled quantities
    def table(self, key: str) -> tuple[np.ndarray, np.ndarray]:
        """(knots, values) of the periodic interpolation of the sampled column ``key`` ("kappa", "wl",
        "wr" or "v"), closed with the first sample at s = L: what :meth:`curvature`, :meth:`width_left`,
        :meth:`width_right` and :meth:`speed` interpolate at wrapped ``s``, for compiled kernels
        (:func:`sofar_env._interp.interp_at`). Read-only views."""
        return self._table_views[key]

    def _interp(self, key: str, s):
        """Periodic linear interpolation of the sampled column ``key`` at ``s`` (scalar or array)."""
        closed, closed_list = self._tables[key]
        sc = _as_scalar(s)
        if sc is not None:
            return self._interp_scalar(closed_list, sc)
        # No wrap of s = L to 0 is needed here (unlike wrap()): the closed table holds the
        # first sample again at s = L, and np.interp returns exactly fp[-1] there.
        return interp(np.mod(np.asarray(s, dtype=float), self.length), self._knots, closed)  # np.interp

    def _interp_scalar(self, closed_list: list, s: float) -> float:
        """:meth:`_interp` at a scalar ``s``, on Python floats.

        Kept instead of ``float(np.interp(...))`` because that form changes bits: it computes
        ``slope * (s - s_i) + f_i``, this ``f_i + w (f_{i+1} - f_i)``, and the two differ in the
        last bit at about 1 point in 3000, which changes seeded trajectories. (It also saves
        about 1.4 % of an env step, measured with cProfile call counts over 1,000 steps of the
        ``bench/bench_env.py`` scenario, 20 scalar calls per step, times 1.1 us per call from
        timeit, against a 1.55 ms step.)
        """
        s = s % self.length
        if s >= self.length:
            s = 0.0
        kl = self._knots_list
        i = bisect.bisect_right(kl, s) - 1
        if i >= self._K:
            i = self._K - 1
        elif i < 0:
            i = 0
        k0 = kl[i]
        w = (s - k0) / (kl[i + 1] - k0)
        return closed_list[i] + w * (closed_list[i + 1] - closed_list[i])

    # The four accessors below call _interp_scalar directly for a Python float or numpy float64
    # (the per-step callers' case: about 30 calls per env step), without the dispatch of _interp.
    def curvature(self, s):
        """Signed curvature of the raceline [1/m] (> 0 in left turns)."""
        kind = type(s)
        if kind is float or kind is np.float64:
            return self._interp_scalar(self._tables["kappa"][1], float(s))
        return self._interp("kappa", s)

    def width_left(self, s):
        """Distance from the raceline to the left edge along the normal [m]."""
        kind = type(s)
        if kind is float or kind is np.float64:
            return self._interp_scalar(self._tables["wl"][1], float(s))
        return self._interp("wl", s)

    def width_right(self, s):
        """Distance from the raceline to the right edge along the normal [m]."""
        kind = type(s)
        if kind is float or kind is np.float64:
            return self._interp_scalar(self._tables["wr"][1], float(s))
        return self._interp("wr", s)

    def speed(self, s):
        """Speed profile [m/s]."""
        kind = type(s)
        if kind is float or kind is np.float64:
            return self._interp_scalar(self._tables["v"][1], float(s))
        return self._interp("v", s)

    # ------------------------------------------------------- spline geometry
    def heading(self, s):
        """Heading of the raceline tangent [rad], measured from the x axis."""
        sc = _as_scalar(s)
        if sc is not None:
            _, _, dx, dy = self._curve.tangent_scalar(self._curve.wrap_scalar(sc))
            return math.atan2(dy, dx)
        _, _, dx, dy = self._curve.eval(self._curve.wrap(np.asarray(s, dtype=float)))
        return np.arctan2(dy, dx)

    def normal(self, s):
        """Unit left normal of the raceline, shape (..., 2)."""
        sc = _as_scalar(s)
        if sc is not None:
            _, _, dx, dy = self._curve.tangent_scalar(self._curve.wrap_scalar(sc))
            r = math.hypot(dx, dy)
            return np.array([-dy / r, dx / r])
        _, _, dx, dy = self._curve.eval(self._curve.wrap(np.asarray(s, dtype=float)))
        r = np.hypot(dx, dy)
        return np.stack([-dy / r, dx / r], axis=-1)

    def to_cartesian(self, s, n):
        """Frenet (s, n) -> Cartesian (x, y) [m]."""
        sc, nc = _as_scalar(s), _as_scalar(n)
        if sc is not None and nc is not None:
            x, y, dx, dy = self._curve.tangent_scalar(self._curve.wrap_scalar(sc))
            r = math.hypot(dx, dy)
            return x - nc * dy / r, y + nc * dx / r
        s_arr, n_arr = np.broadcast_arrays(np.asarray(s, dtype=float), np.asarray(n, dtype=float))
        x, y, dx, dy = self._curve.eval(self._curve.wrap(s_arr))
        r = np.hypot(dx, dy)
        return x - n_arr * dy / r, y + n_arr * dx / r

    def pose(self, s: float, n: float) -> tuple[float, float, float]:
        """(x, y, heading) of the point (s, n) of a car aligned with the raceline, for scalar s and n:
        ``to_cartesian(s, n)`` and ``heading(s)`` (the same values) from one spline evaluation."""
        x, y, dx, dy = self._curve.tangent_scalar(self._curve.wrap_scalar(float(s)))
        n = float(n)
        r = math.hypot(dx, dy)
        return x - n * dy / r, y + n * dx / r, math.atan2(dy, dx)

    def poses(self, s: np.ndarray, n: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`pose` at each point (s[i], n[i]) of two 1-D float arrays: arrays (x, y, heading), the same
        values. The spline pieces and headings come from one compiled call (:func:`.curve.tangents_into`); the
        normal's length stays ``math.hypot`` (numpy's and numba's hypot differ from it in the last bit)."""
        tan = np.empty((len(s), 5))
        tangents_into(s, self._knots, self._coefs, self._curve._last, self.length, tan)
        xs, ys, hypot = [], [], math.hypot
        for (x, y, dx, dy, _), nk in zip(tan.tolist(), n.tolist()):
            r = hypot(dx, dy)
            xs.append(x - nk * dy / r)
            ys.append(y + nk * dx / r)
        return np.array(xs, dtype=float), np.array(ys, dtype=float), tan[:, 4].copy()

    def to_frenet(self, x, y, s_hint=None):
        """Cartesian (x, y) -> Frenet (s, n): exact projection onto the raceline spline.

        Without ``s_hint`` the nearest raceline sample (KD-tree) seeds a Newton
        refinement; with ``s_hint`` (a previous s) only a local window around it
        is searched, so the result stays on the same stretch of track.
        """
        xs, ys = _as_scalar(x), _as_scalar(y)
        hs = None if s_hint is None else _as_scalar(s_hint)
        if xs is not None and ys is not None and (s_hint is None or hs is not None):
            return self._to_frenet_scalar(xs, ys, hs)
        if s_hint is None:
            xa, ya = np.broadcast_arrays(np.asarray(x, dtype=float), np.asarray(y, dtype=float))
        else:
            xa, ya, ha = np.broadcast_arrays(
                np.asarray(x, dtype=float), np.asarray(y, dtype=float), np.asarray(s_hint, dtype=float)
            )
        shape = xa.shape
        px, py = xa.ravel(), ya.ravel()
        if s_hint is None:
            _, idx = self._tree.query(np.column_stack([px, py]))
        else:
            idx = self._window_search(px, py, self._curve.wrap(ha.ravel()))
        s, n = self._newton(px, py, self.s[idx])
        return s.reshape(shape), n.reshape(shape)

    def _window_search(self, px: np.ndarray, py: np.ndarray, hint: np.ndarray) -> np.ndarray:
        i0 = np.clip(np.searchsorted(self._knots, hint, side="right") - 1, 0, self._K - 1)
        cand = (i0[:, None] + self._hint_offsets[None, :]) % self._K
        d2 = (self.xy[cand, 0] - px[:, None]) ** 2 + (self.xy[cand, 1] - py[:, None]) ** 2
        return cand[np.arange(len(px)), np.argmin(d2, axis=1)]

    def _newton(self, px: np.ndarray, py: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        curve = self._curve
        s = s.astype(float).copy()
        active = np.ones(len(s), dtype=bool)
        for _ in range(_NEWTON_MAX_ITER):
            if not active.any():
                break
            sa = s[active]
            x, y, dx, dy, ddx, ddy = curve.eval(sa, order=2)
            ex, ey = x - px[active], y - py[active]
            g = ex * dx + ey * dy
            dd = dx * dx + dy * dy
            h = dd + ex * ddx + ey * ddy
            h = np.where(h < 0.2 * dd, dd, h)
            step = np.clip(-g / h, -self._max_step, self._max_step)
            s[active] = curve.wrap(sa + step)
            done = np.abs(step) < _NEWTON_TOL
            idx = np.flatnonzero(active)
            active[idx[done]] = False
        x, y, dx, dy = curve.eval(s)
        r = np.hypot(dx, dy)
        n = (dx * (py - y) - dy * (px - x)) / r
        return s, n

    def _to_frenet_scalar(self, x: float, y: float, hint: float | None) -> tuple[float, float]:
        curve = self._curve
        if hint is None:
            _, i = self._tree.query((x, y))
            s = self._knots_list[int(i)]
        else:
            s = curve.wrap_scalar(hint)
        result = self._newton_scalar(x, y, s)
        if result is None or (hint is not None and abs(self._gap_scalar(result[0], s)) > _HINT_WINDOW):
            # Newton from the hint failed or ran away: seed from the window search.
            if hint is None:
                seed = s
            else:
                seed = float(self.s[self._window_search(np.array([x]), np.array([y]), np.array([s]))[0]])
            result = self._newton_scalar(x, y, seed, robust=True)
        return result

    def _newton_scalar(self, x: float, y: float, s: float, robust: bool = False):
        """:meth:`_newton` for one point (one compiled call, :func:`_newton_point`); None if it has not
        converged (unless ``robust``)."""
        curve = self._curve
        converged, s, px, py, dx, dy = _newton_point(x, y, s, curve.knots, self._coefs, curve._last, curve.length,
                                                     self._max_step, _NEWTON_MAX_ITER, _NEWTON_TOL)
        if not converged and not robust:
            return None
        return s, (dx * (y - py) - dy * (x - px)) / math.hypot(dx, dy)

    # ---------------------------------------------------------------- misc
    def spline_curvature(self, s):
        """Curvature of the position spline itself [1/m] (for diagnostics)."""
        return self._curve.curvature(self._curve.wrap(np.asarray(s, dtype=float)))



@kernel
def _newton_point(x, y, s, knots, coefs, last, length, max_step, max_iter, tol):
    """Newton projection of the point (x, y) onto the raceline spline from arc length ``s``:
    ``(converged, s, x(s), y(s), x'(s), y'(s))``. Each iteration evaluates the cubic piece holding
    ``s`` (the piece whose knot is the last one <= s, as ``bisect_right``), steps by ``-g / h`` (``g``
    the gradient of half the squared distance, ``h`` its second derivative, replaced by ``|r'|^2``
    where below ``0.2 |r'|^2``), the step clipped to ``max_step`` (as Python's ``min``/``max`` pick),
    and wraps ``s`` into [0, length); it stops when the step is below ``tol``."""
    converged = False
    for _ in range(max_iter):
        i = _piece(knots, s, last)
        t = s - knots[i]
        a, b, c, d, e, f, g, hh = coefs[i, 0], coefs[i, 1], coefs[i, 2], coefs[i, 3], coefs[i, 4], \
            coefs[i, 5], coefs[i, 6], coefs[i, 7]
        px = ((a * t + b) * t + c) * t + d
        py = ((e * t + f) * t + g) * t + hh
        dx = (3.0 * a * t + 2.0 * b) * t + c
        dy = (3.0 * e * t + 2.0 * f) * t + g
        ddx = 6.0 * a * t + 2.0 * b
        ddy = 6.0 * e * t + 2.0 * f
        ex, ey = px - x, py - y
        dd = dx * dx + dy * dy
        h = dd + ex * ddx + ey * ddy
        if h < 0.2 * dd:
            h = dd
        step = -(ex * dx + ey * dy) / h
        if -max_step > step:
            step = -max_step
        if max_step < step:
            step = max_step
        s = (s + step) % length
        if s >= length:
            s = 0.0
        if -tol < step < tol:
            converged = True
            break
    i = _piece(knots, s, last)
    t = s - knots[i]
    a, b, c, d, e, f, g, hh = coefs[i, 0], coefs[i, 1], coefs[i, 2], coefs[i, 3], coefs[i, 4], coefs[i, 5], \
        coefs[i, 6], coefs[i, 7]
    return (converged, s, ((a * t + b) * t + c) * t + d, ((e * t + f) * t + g) * t + hh,
            (3.0 * a * t + 2.0 * b) * t + c, (3.0 * e * t + 2.0 * f) * t + g)


@kernel
def _piece(knots, s, last):
    """``bisect_right(knots, s) - 1`` clipped to ``[0, last]``: the spline piece holding ``s``."""
    i = locate(s, knots, -1)
    return min(max(i, 0), last)

