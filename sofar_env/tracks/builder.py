"""Circuit builder: track edges -> centreline -> minimum-curvature raceline -> speed profile.

Pipeline (all geometry in metres):

1. The two edges are resampled at uniform arc length and lightly smoothed
   (periodic Gaussian, moves points by centimetres).  A centreline is found by
   pairing the edges and re-centring it along its normals.
2. A raceline is computed as a minimum-curvature QP: a lateral shift
   ``alpha_i`` along the normals of a reference line, curvature linearised
   around the reference, solved with OSQP, iterated with the previous solution
   as the new reference.  The shift is bounded so the raceline keeps at least
   ``clearance`` metres from each edge; the clearance is verified afterwards
   with exact point-to-polyline distances and the bounds are tightened locally
   and the QP re-solved where needed.
3. The raceline is resampled at uniform arc length; heading and signed
   curvature come from the periodic cubic spline that :class:`Track` uses,
   widths from ray-edge intersections along the normal.
4. A speed profile from a forward-backward pass (lateral acceleration limit,
   acceleration and braking limits, top speed) on the closed loop.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import logging
import math
import os
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.interpolate import CubicSpline
from scipy.ndimage import gaussian_filter1d
from scipy import sparse
from scipy.spatial import cKDTree

from .track import (
    EDGE_COLUMNS,
    FORMAT_VERSION,
    LEFT_EDGE_FILE,
    META_FILE,
    RACELINE_COLUMNS,
    RACELINE_FILE,
    RIGHT_EDGE_FILE,
    PeriodicCurve,
    Track,
    TrackFormatError,
)

__all__ = [
    "BuildConfig",
    "CENTERLINE_FILE",
    "build_track",
    "build_from_edges",
    "read_edges_csv",
    "read_centerline_csv",
    "speed_profile",
    "polyline_distance",
    "ray_polyline_distance",
]

logger = logging.getLogger(__name__)

CENTERLINE_FILE = "centerline.csv"
_NARROW_SLACK = 0.05  # [m] lateral freedom around the centre where the corridor is too narrow
CENTERLINE_COLUMNS = ("s_m", "x_m", "y_m", "w_left_m", "w_right_m")
PROVENANCE = (
    "Edge positions of the public raceway as published by the SOfAR paper authors "
    "(github.com/hassanjardali/SOfAR); only the edge positions were taken. Resampled "
    "edges, centreline, widths, raceline, curvature and speed profile were computed "
    "by the sofar_env.tracks builder."
)


@dataclass(frozen=True)
class BuildConfig:
    """Parameters of the circuit builder."""

    clearance: float = 2.0
    """Minimum distance from the raceline to each edge polyline [m]."""
    top_speed: float = 85.0
    """Speed cap of the speed profile [m/s]."""
    a_lat_max: float = 15.0
    """Lateral acceleration limit, v^2 |kappa| <= a_lat_max [m/s^2]."""
    a_accel_max: float = 3.0
    """Longitudinal acceleration limit [m/s^2]."""
    a_brake_max: float = 10.0
    """Longitudinal deceleration limit (positive number) [m/s^2]."""
    spacing: float = 1.0
    """Arc-length spacing of the stored raceline, edges and centreline [m]."""
    qp_spacing: float = 2.0
    """Spacing of the reference line inside the minimum-curvature QP [m]."""
    qp_iterations: int = 5
    """Number of QP solves, each linearised around the previous raceline [-]."""
    qp_regularization: float = 1e-8
    """Weight of the sum of alpha^2 next to the sum of (h^2 kappa)^2 in the QP [1/m^2]
    (keeps the Hessian positive definite)."""
    raceline_smoothing: float = 10.0
    """Weight of the periodic Whittaker smoother applied to the QP solution before
    it becomes the raceline; removes millimetre ripples inherited from the edge
    data (0 disables) [-]."""
    qp_margin: float = 0.02
    """Extra shift margin added to the clearance inside the QP [m]."""
    edge_smoothing: float = 1.0
    """Standard deviation of the periodic Gaussian smoothing of the edges [m]."""
    centerline_smoothing: float = 6.0
    """Standard deviation of the Gaussian smoothing of the centreline [m]."""
    max_repairs: int = 12
    """Maximum number of clearance repair rounds (tighten bounds, re-solve) [-]."""

    def validate(self) -> None:
        for field in dataclasses.fields(self):
            value = getattr(self, field.name)
            if not (isinstance(value, (int, float)) and math.isfinite(value)) or value < 0:
                raise ValueError(f"BuildConfig.{field.name} must be a finite non-negative number, got {value!r}")
        for name in ("top_speed", "a_lat_max", "a_accel_max", "a_brake_max", "spacing", "qp_spacing"):
            if getattr(self, name) <= 0:
                raise ValueError(f"BuildConfig.{name} must be positive")
        if self.qp_iterations < 1:
            raise ValueError("BuildConfig.qp_iterations must be at least 1")
        if self.clearance < 1.0:
            warnings.warn(
                f"clearance {self.clearance} m is below 1.0 m: opponents at +-1 m from the raceline "
                "may leave the track",
                stacklevel=3,
            )


# ---------------------------------------------------------------- input files


def _sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 16), b""):
            digest.update(block)
    return digest.hexdigest()


def _read_numeric_csv(path: Path, ncols: int) -> np.ndarray:
    """Numeric rows of a CSV; '#' comment lines and one non-numeric header line are skipped."""
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise TrackFormatError(f"{path}: file not found") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise TrackFormatError(f"{path}: cannot read ({exc})") from None
    rows = []
    for lineno, raw in enumerate(text.splitlines(), start=1):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        fields = [f.strip() for f in line.split(",")]
        try:
            values = [float(f) if f else math.nan for f in fields]
        except ValueError:
            if not rows:  # a header line
                continue
            raise TrackFormatError(f"{path}: line {lineno}: non-numeric value") from None
        if len(values) != ncols:
            raise TrackFormatError(f"{path}: line {lineno} has {len(values)} fields, expected {ncols}")
        rows.append(values)
    if not rows:
        raise TrackFormatError(f"{path}: no data rows")
    return np.array(rows, dtype=float)


def _clean_closed(points: np.ndarray, label: str) -> np.ndarray:
    """Drop non-finite rows, repeated points and a repeated closing point."""
    points = points[np.all(np.isfinite(points), axis=1)]
    if len(points) > 1:
        step = np.hypot(*np.diff(points, axis=0).T)
        points = points[np.concatenate([[True], step > 1e-9])]
    if len(points) > 1 and np.hypot(*(points[-1] - points[0])) < 1e-9:
        points = points[:-1]
    if len(points) < 8:
        raise TrackFormatError(f"{label}: fewer than 8 distinct points")
    return points


def read_edges_csv(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray]:
    """Edges file ``left_x, left_y, right_x, right_y`` -> (left, right) point arrays.

    Rows need not be paired; an edge may be padded with empty/NaN fields.
    """
    path = Path(path)
    data = _read_numeric_csv(path, 4)
    return _clean_closed(data[:, :2], f"{path} (left edge)"), _clean_closed(data[:, 2:], f"{path} (right edge)")


def read_centerline_csv(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray]:
    """Centreline file ``x_m, y_m, w_tr_right_m, w_tr_left_m`` -> (left, right) edges."""
    path = Path(path)
    data = _read_numeric_csv(path, 4)
    data = data[np.all(np.isfinite(data), axis=1)]
    center = _clean_closed(data[:, :2], str(path))
    # widths of the rows that survived the cleaning (matched by position)
    tree = cKDTree(data[:, :2])
    _, idx = tree.query(center)
    w_right, w_left = data[idx, 2], data[idx, 3]
    if np.any(w_right <= 0) or np.any(w_left <= 0):
        raise TrackFormatError(f"{path}: track widths must be positive")
    tangent = np.roll(center, -1, axis=0) - np.roll(center, 1, axis=0)
    tangent /= np.hypot(*tangent.T)[:, None]
    normal = np.column_stack([-tangent[:, 1], tangent[:, 0]])
    return center + w_left[:, None] * normal, center - w_right[:, None] * normal


# ------------------------------------------------------------ polyline tools


def _signed_area(points: np.ndarray) -> float:
    x, y = points[:, 0], points[:, 1]
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def _closed_cumlength(points: np.ndarray) -> np.ndarray:
    closed = np.vstack([points, points[:1]])
    return np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(closed, axis=0).T))])


def resample_closed(points: np.ndarray, spacing: float) -> np.ndarray:
    """Closed polyline resampled by linear interpolation at uniform arc length."""
    cum = _closed_cumlength(points)
    length = cum[-1]
    count = max(8, int(round(length / spacing)))
    t = np.arange(count) * (length / count)
    closed = np.vstack([points, points[:1]])
    return np.column_stack([np.interp(t, cum, closed[:, 0]), np.interp(t, cum, closed[:, 1])])


def periodic_smooth(points: np.ndarray, weight: float) -> np.ndarray:
    """Discrete periodic smoothing spline (Whittaker smoother) of a closed polyline.

    Solves (I + weight * D2' D2) z = p with D2 the periodic second difference;
    ripples a few samples long are removed, while a curve of curvature kappa
    sampled every h moves by about weight * h^4 * |kappa'' + kappa^3| only.
    """
    n = len(points)
    idx = np.arange(n)
    d2 = sparse.csc_matrix(
        (np.concatenate([np.ones(n), -2.0 * np.ones(n), np.ones(n)]),
         (np.tile(idx, 3), np.concatenate([(idx - 1) % n, idx, (idx + 1) % n]))),
        shape=(n, n),
    )
    system = (sparse.identity(n, format="csc") + weight * (d2.T @ d2)).tocsc()
    from scipy.sparse.linalg import splu

    lu = splu(system)
    return np.column_stack([lu.solve(np.ascontiguousarray(points[:, k])) for k in range(2)])


def spline_resample_closed(
    points: np.ndarray, spacing: float, smoothing: float = 0.0, oversample: int = 16
) -> tuple[np.ndarray, float]:
    """Closed curve through ``points`` resampled at uniform arc length.

    The curve is the periodic cubic spline through the points in the
    chord-length parameter, after :func:`periodic_smooth` with weight
    ``smoothing`` when it is positive.  Returns (samples, closed length).
    """
    if smoothing > 0.0:
        points = periodic_smooth(points, smoothing)
    cum = _closed_cumlength(points)
    closed = np.vstack([points, points[:1]])
    sx = CubicSpline(cum, closed[:, 0], bc_type="periodic")
    sy = CubicSpline(cum, closed[:, 1], bc_type="periodic")

    def evaluate(u: np.ndarray, der: int = 0) -> tuple[np.ndarray, np.ndarray]:
        return sx(u, der), sy(u, der)

    u = np.linspace(0.0, cum[-1], oversample * len(points) + 1)
    # arc length: trapezoidal rule for |r'(u)| on a fine grid
    speed = np.hypot(*evaluate(u, 1))
    arc = np.concatenate([[0.0], np.cumsum(0.5 * (speed[1:] + speed[:-1]) * np.diff(u))])
    length = float(arc[-1])
    count = max(8, int(round(length / spacing)))
    target = np.arange(count) * (length / count)
    uu = np.interp(target, arc, u)
    for _ in range(2):  # Newton corrections of the parameter of each target arc length
        uu = uu + (target - np.interp(uu, u, arc)) / np.hypot(*evaluate(uu, 1))
    return np.column_stack(evaluate(uu)), length


def _tangent_normal(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    tangent = np.roll(points, -1, axis=0) - np.roll(points, 1, axis=0)
    tangent /= np.hypot(*tangent.T)[:, None]
    return tangent, np.column_stack([-tangent[:, 1], tangent[:, 0]])


def _segments(poly: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    start = poly
    vec = np.roll(poly, -1, axis=0) - poly
    return start, vec


def polyline_distance(points: np.ndarray, poly: np.ndarray, chunk: int = 256) -> np.ndarray:
    """Exact distance from each point to the closed polyline ``poly`` (brute force, chunked)."""
    points = np.atleast_2d(np.asarray(points, dtype=float))
    start, vec = _segments(np.asarray(poly, dtype=float))
    len2 = np.maximum(np.einsum("ij,ij->i", vec, vec), 1e-300)
    out = np.empty(len(points))
    for lo in range(0, len(points), chunk):
        p = points[lo : lo + chunk]
        wx = p[:, 0:1] - start[None, :, 0]
        wy = p[:, 1:2] - start[None, :, 1]
        t = np.clip((wx * vec[None, :, 0] + wy * vec[None, :, 1]) / len2[None, :], 0.0, 1.0)
        dx = wx - t * vec[None, :, 0]
        dy = wy - t * vec[None, :, 1]
        out[lo : lo + chunk] = np.sqrt(np.min(dx * dx + dy * dy, axis=1))
    return out


def ray_polyline_distance(origins: np.ndarray, directions: np.ndarray, poly: np.ndarray, chunk: int = 256) -> np.ndarray:
    """Smallest t > 0 with origin + t * direction on the closed polyline (inf if none)."""
    start, vec = _segments(np.asarray(poly, dtype=float))
    out = np.full(len(origins), np.inf)
    for lo in range(0, len(origins), chunk):
        o = origins[lo : lo + chunk]
        d = directions[lo : lo + chunk]
        denom = d[:, 0:1] * vec[None, :, 1] - d[:, 1:2] * vec[None, :, 0]
        wx = start[None, :, 0] - o[:, 0:1]
        wy = start[None, :, 1] - o[:, 1:2]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (wx * vec[None, :, 1] - wy * vec[None, :, 0]) / denom
            u = (wx * d[:, 1:2] - wy * d[:, 0:1]) / denom
        ok = (np.abs(denom) > 1e-12) & (u >= -1e-9) & (u <= 1.0 + 1e-9) & (t > 0.0)
        out[lo : lo + chunk] = np.min(np.where(ok, t, np.inf), axis=1)
    return out


def _closest_points(points: np.ndarray, poly: np.ndarray, chunk: int = 256) -> np.ndarray:
    start, vec = _segments(poly)
    len2 = np.maximum(np.einsum("ij,ij->i", vec, vec), 1e-300)
    out = np.empty_like(points)
    for lo in range(0, len(points), chunk):
        p = points[lo : lo + chunk]
        wx = p[:, 0:1] - start[None, :, 0]
        wy = p[:, 1:2] - start[None, :, 1]
        t = np.clip((wx * vec[None, :, 0] + wy * vec[None, :, 1]) / len2[None, :], 0.0, 1.0)
        d2 = (wx - t * vec[None, :, 0]) ** 2 + (wy - t * vec[None, :, 1]) ** 2
        j = np.argmin(d2, axis=1)
        tj = t[np.arange(len(p)), j]
        out[lo : lo + chunk] = start[j] + tj[:, None] * vec[j]
    return out


def _widths(points: np.ndarray, normal: np.ndarray, left: np.ndarray, right: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distances along +normal to the left edge and along -normal to the right edge."""
    wl = ray_polyline_distance(points, normal, left)
    wr = ray_polyline_distance(points, -normal, right)
    for w, edge, label in ((wl, left, "left"), (wr, right, "right")):
        miss = ~np.isfinite(w)
        if miss.any():
            logger.warning("%d normals miss the %s edge; using the point-to-edge distance", miss.sum(), label)
            w[miss] = polyline_distance(points[miss], edge)
    return wl, wr


# ------------------------------------------------------------------ edges


def _orient_edges(left: np.ndarray, right: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Order both edges in the driving direction implied by the left/right labels."""
    a_left, a_right = _signed_area(left), _signed_area(right)
    if np.sign(a_left) != np.sign(a_right):
        logger.info("right edge listed against the left edge's direction; reversing it")
        right = right[::-1].copy()
        a_right = -a_right
    # Driving along the point order: counter-clockwise puts the left edge inside
    # (smaller area), clockwise puts it outside.
    ccw = a_left > 0
    left_inside = abs(a_left) < abs(a_right)
    if ccw != left_inside:
        logger.warning("edge point order runs against the left/right labels; reversing the driving direction")
        left, right = left[::-1].copy(), right[::-1].copy()
    return left, right


def _prepare_edge(points: np.ndarray, config: BuildConfig) -> tuple[np.ndarray, float]:
    """Uniformly resampled, lightly smoothed closed edge and the max smoothing displacement."""
    res = resample_closed(points, config.spacing)
    if config.edge_smoothing <= 0:
        return res, 0.0
    sigma = config.edge_smoothing / config.spacing
    smooth = np.column_stack([gaussian_filter1d(res[:, k], sigma, mode="wrap") for k in range(2)])
    return smooth, float(np.max(polyline_distance(smooth, points)))


def _centerline(left: np.ndarray, right: np.ndarray, config: BuildConfig) -> np.ndarray:
    """Closed centreline at ``qp_spacing``, equidistant from the edges along its normals."""
    mid = 0.5 * (left + _closest_points(left, right))
    sigma = config.centerline_smoothing / config.qp_spacing
    center = resample_closed(mid, config.qp_spacing)
    for _ in range(4):
        center = np.column_stack([gaussian_filter1d(center[:, k], sigma, mode="wrap") for k in range(2)])
        center, _ = spline_resample_closed(center, config.qp_spacing)
        _, normal = _tangent_normal(center)
        wl, wr = _widths(center, normal, left, right)
        center = center + (0.5 * (wl - wr))[:, None] * normal
        center, _ = spline_resample_closed(center, config.qp_spacing)
    return center


# ---------------------------------------------------------- raceline (QP)


def _solve_qp(P: sparse.csc_matrix, q: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """min 1/2 x'Px + q'x subject to lo <= x <= hi, solved with OSQP.

    The curvature Hessian is ill-conditioned only in its smooth, nearly
    curvature-free modes (slow lateral drifts along long straights), where ADMM
    converges slowly.  Errors in those modes barely change the curvature, so an
    iteration cap is accepted; the bounds are enforced by clipping and the
    clearance is verified afterwards anyway.
    """
    import osqp  # imported lazily: only the builder needs it

    n = len(q)
    settings = dict(verbose=False, eps_abs=1e-5, eps_rel=1e-5, max_iter=20000, adaptive_rho_interval=25)
    major = int(str(getattr(osqp, "__version__", "1")).split(".")[0])
    settings["polishing" if major >= 1 else "polish"] = False
    solver = osqp.OSQP()
    solver.setup(sparse.triu(P, format="csc"), q, sparse.identity(n, format="csc"), lo, hi, **settings)
    try:
        result = solver.solve(raise_error=False)
    except TypeError:  # osqp < 1.0 has no raise_error argument
        result = solver.solve()
    status = str(result.info.status).lower()
    usable = "solved" in status or "maximum iterations" in status
    if not usable or result.x is None or not np.all(np.isfinite(result.x)):
        raise RuntimeError(f"minimum-curvature QP failed: OSQP status {result.info.status!r}")
    logger.info("OSQP: %s after %d iterations", result.info.status, result.info.iter)
    return np.clip(result.x, lo, hi)


def _curvature_jacobian(ref: np.ndarray, normal: np.ndarray) -> tuple[np.ndarray, sparse.csc_matrix]:
    """Discrete curvature of the closed polyline ``ref`` and its Jacobian with
    respect to shifts alpha along ``normal``.

    kappa_i = u x w / |u|^3 with u = (P_{i+1} - P_{i-1}) / 2 and
    w = P_{i+1} - 2 P_i + P_{i-1}; the Jacobian is tridiagonal (periodic).
    """
    n = len(ref)
    nxt, prv = np.roll(ref, -1, axis=0), np.roll(ref, 1, axis=0)
    u = 0.5 * (nxt - prv)
    w = nxt - 2.0 * ref + prv
    m2 = np.einsum("ij,ij->i", u, u)
    m = np.sqrt(m2)
    c = u[:, 0] * w[:, 1] - u[:, 1] * w[:, 0]
    kappa = c / (m2 * m)
    idx = np.arange(n)
    rows, cols, vals = [], [], []
    # d u / d alpha_j and d w / d alpha_j for j = i-1, i, i+1
    for offset, du_coef, dw_coef in ((-1, -0.5, 1.0), (0, 0.0, -2.0), (1, 0.5, 1.0)):
        j = (idx + offset) % n
        nj = normal[j]
        du = du_coef * nj
        dw = dw_coef * nj
        dc = (du[:, 0] * w[:, 1] - du[:, 1] * w[:, 0]) + (u[:, 0] * dw[:, 1] - u[:, 1] * dw[:, 0])
        dm2 = 2.0 * np.einsum("ij,ij->i", u, du)
        dk = dc / (m2 * m) - 1.5 * c * dm2 / (m2 * m2 * m)
        rows.append(idx)
        cols.append(j)
        vals.append(dk)
    jac = sparse.csc_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(n, n))
    return kappa, jac


def _min_curvature_shift(ref: np.ndarray, lo: np.ndarray, hi: np.ndarray, regularization: float) -> np.ndarray:
    """Shift alpha along the normals of the uniform closed ``ref`` minimising sum kappa_i^2,
    with the curvature linearised around the reference (kappa ~ kappa_ref + J alpha)."""
    n = len(ref)
    _, normal = _tangent_normal(ref)
    kappa, jac = _curvature_jacobian(ref, normal)
    h2 = float(np.mean(np.hypot(*(np.roll(ref, -1, axis=0) - ref).T))) ** 2
    A = (h2 * jac).tocsc()  # scaled so that its entries are of order one
    b = h2 * kappa
    P = 2.0 * (A.T @ A + regularization * sparse.identity(n))
    q = 2.0 * (A.T @ b)
    return _solve_qp(P.tocsc(), q, lo, hi)


def _bounds(ref: np.ndarray, left: np.ndarray, right: np.ndarray, margin: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Shift bounds along the normals of ``ref`` and the corridor mask that is too narrow."""
    _, normal = _tangent_normal(ref)
    wl, wr = _widths(ref, normal, left, right)
    lo, hi = -(wr - margin), wl - margin
    narrow = lo > hi
    if narrow.any():
        # centre the line, with a few centimetres of slack so that the QP can
        # still smooth out the small ripples of the edge data
        mid = 0.5 * (wl - wr)
        lo = np.where(narrow, mid - _NARROW_SLACK, lo)
        hi = np.where(narrow, mid + _NARROW_SLACK, hi)
    return lo, hi, normal, narrow


@dataclass
class _Raceline:
    ref: np.ndarray
    alpha: np.ndarray
    normal: np.ndarray
    narrow: np.ndarray

    @property
    def points(self) -> np.ndarray:
        return self.ref + self.alpha[:, None] * self.normal


def _raceline(center: np.ndarray, left: np.ndarray, right: np.ndarray, config: BuildConfig) -> _Raceline:
    ref = center
    base = config.clearance + config.qp_margin
    result = None
    for it in range(config.qp_iterations):
        margin = np.full(len(ref), base)
        lo, hi, normal, narrow = _bounds(ref, left, right, margin)
        alpha = _min_curvature_shift(ref, lo, hi, config.qp_regularization)
        result = _Raceline(ref, alpha, normal, narrow)
        logger.info("QP iteration %d: max |shift| %.3f m", it + 1, float(np.max(np.abs(alpha))))
        if it < config.qp_iterations - 1:
            ref, _ = spline_resample_closed(result.points, config.qp_spacing)
    assert result is not None
    return result


# ------------------------------------------------------------ speed profile


def speed_profile(
    kappa: np.ndarray, ds: np.ndarray, a_lat_max: float, a_accel_max: float, a_brake_max: float, top_speed: float
) -> np.ndarray:
    """Closed-loop speed profile.

    ``ds[i]`` is the arc length from sample i to sample i+1 (the last entry
    closes the loop).  Enforces v^2 |kappa| <= a_lat_max, v <= top_speed and
    (v_{i+1}^2 - v_i^2) / (2 ds_i) in [-a_brake_max, a_accel_max].
    """
    kappa = np.asarray(kappa, dtype=float)
    with np.errstate(divide="ignore"):
        vmax = np.where(np.abs(kappa) > 1e-12, np.sqrt(a_lat_max / np.abs(kappa)), np.inf)
    vmax = np.minimum(vmax, top_speed)
    n = len(vmax)
    start = int(np.argmin(vmax))  # this sample is never lowered by the passes below
    v = np.roll(vmax, -start).tolist()
    d = np.roll(np.asarray(ds, dtype=float), -start).tolist()
    for _ in range(10):
        before = list(v)
        for j in range(n):  # acceleration limit, forward
            k = (j + 1) % n
            reach = math.sqrt(v[j] * v[j] + 2.0 * a_accel_max * d[j])
            if v[k] > reach:
                v[k] = reach
        for j in range(n - 1, -1, -1):  # braking limit, backward
            k = (j + 1) % n
            reach = math.sqrt(v[k] * v[k] + 2.0 * a_brake_max * d[j])
            if v[j] > reach:
                v[j] = reach
        if v == before:
            break
    return np.roll(np.array(v), start)


def lap_time(v: np.ndarray, ds: np.ndarray) -> float:
    """Lap time of a closed speed profile with constant acceleration between samples [s]."""
    return float(np.sum(2.0 * ds / (v + np.roll(v, -1))))


# ---------------------------------------------------------------- assembly


@dataclass
class BuiltCircuit:
    """Arrays and metadata of a built circuit (what is written to disk)."""

    raceline: np.ndarray  # (K, 8) columns RACELINE_COLUMNS
    left_edge: np.ndarray
    right_edge: np.ndarray
    centerline: np.ndarray  # (C, 5) columns CENTERLINE_COLUMNS
    meta: dict

    def to_track(self) -> Track:
        return Track(self.meta["name"], self.meta["length_m"], self.raceline, self.left_edge, self.right_edge, self.meta)


def _finish(points: np.ndarray, anchor: np.ndarray, config: BuildConfig) -> tuple[np.ndarray, float, PeriodicCurve]:
    """Uniform raceline samples starting near ``anchor`` and their spline."""
    start = int(np.argmin(np.hypot(*(points - anchor).T)))
    samples, length = spline_resample_closed(
        np.roll(points, -start, axis=0), config.spacing, smoothing=config.raceline_smoothing
    )
    s = np.arange(len(samples)) * (length / len(samples))
    return s, length, PeriodicCurve(s, samples, length)


def _clearances(curve: PeriodicCurve, s: np.ndarray, left: np.ndarray, right: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Edge distances at the samples and half-way between them."""
    ds = curve.length / len(s)
    dense = np.concatenate([s, s + 0.5 * ds])
    x, y, _, _ = curve.eval(curve.wrap(dense))
    pts = np.column_stack([x, y])
    return pts, polyline_distance(pts, left), polyline_distance(pts, right)


def _round_sig(values: np.ndarray, digits: int = 12) -> np.ndarray:
    """Values rounded as the ``%.{digits}g`` format stores them."""
    return np.array([float(f"{v:.{digits}g}") for v in values])


def build_from_edges(
    left: np.ndarray,
    right: np.ndarray,
    name: str,
    config: BuildConfig | None = None,
    source: dict | None = None,
) -> BuiltCircuit:
    """Build a circuit from two closed edges (left = +n side in the driving direction)."""
    config = config or BuildConfig()
    config.validate()
    left = _clean_closed(np.asarray(left, dtype=float), "left edge")
    right = _clean_closed(np.asarray(right, dtype=float), "right edge")
    left, right = _orient_edges(left, right)
    anchor = 0.5 * (left[0] + _closest_points(left[:1], right)[0])

    left_s, disp_l = _prepare_edge(left, config)
    right_s, disp_r = _prepare_edge(right, config)
    logger.info("edge smoothing moved points by at most %.3f m", max(disp_l, disp_r))

    center = _centerline(left_s, right_s, config)
    race = _raceline(center, left_s, right_s, config)

    # Verify the clearance exactly; tighten the bounds where it is short and re-solve.
    ref_tree = cKDTree(race.ref)
    margin = np.full(len(race.ref), config.clearance + config.qp_margin)
    for repair in range(config.max_repairs + 1):
        s, length, curve = _finish(race.points, anchor, config)
        pts, d_left, d_right = _clearances(curve, s, left_s, right_s)
        # enforce the clearance to the stored (smoothed) and to the source edges
        need_l = np.minimum(d_left, polyline_distance(pts, left))
        need_r = np.minimum(d_right, polyline_distance(pts, right))
        _, near = ref_tree.query(pts)
        excused = race.narrow[near]
        short_l = (need_l < config.clearance) & ~excused
        short_r = (need_r < config.clearance) & ~excused
        if not (short_l.any() or short_r.any()):
            break
        if repair == config.max_repairs:
            raise RuntimeError(
                f"{name}: raceline clearance {min(need_l.min(), need_r.min()):.3f} m below "
                f"{config.clearance} m after {config.max_repairs} repairs"
            )
        deficit = np.zeros(len(race.ref))
        for short, dist in ((short_l, need_l), (short_r, need_r)):
            for node, dd in zip(near[short], config.clearance - dist[short]):
                for k in range(-3, 4):
                    j = (node + k) % len(deficit)
                    deficit[j] = max(deficit[j], dd)
        margin = margin + np.where(deficit > 0, deficit + 0.01, 0.0)
        logger.info("clearance repair %d: %d samples short by up to %.3f m", repair + 1,
                    int(short_l.sum() + short_r.sum()), float(deficit.max()))
        lo, hi, normal, narrow = _bounds(race.ref, left_s, right_s, margin)
        race = _Raceline(race.ref, _min_curvature_shift(race.ref, lo, hi, config.qp_regularization), normal, narrow | race.narrow)
    if race.narrow.any():
        warnings.warn(
            f"{name}: corridor narrower than 2 x clearance at {int(race.narrow.sum())} QP nodes; "
            "the raceline is centred there",
            stacklevel=2,
        )

    x, y, dx, dy, ddx, ddy = curve.eval(s, order=2)
    xy = np.column_stack([x, y])
    speed2 = dx * dx + dy * dy
    psi = np.arctan2(dy, dx)
    kappa = (dx * ddy - dy * ddx) / np.power(speed2, 1.5)
    normal = np.column_stack([-dy, dx]) / np.sqrt(speed2)[:, None]
    w_left, w_right = _widths(xy, normal, left_s, right_s)
    # The speed profile is computed from the values exactly as they are stored
    # (s and L rounded to the micrometre, kappa to 12 digits) so that the stored
    # columns satisfy the limits to rounding error.
    length = round(float(length), 6)
    s = np.round(s, 6)
    kappa = _round_sig(kappa)
    ds = np.diff(np.append(s, length))
    v = _round_sig(speed_profile(kappa, ds, config.a_lat_max, config.a_accel_max, config.a_brake_max, config.top_speed))
    raceline = np.column_stack([s, x, y, psi, kappa, w_left, w_right, v])

    # centreline with widths, at the output spacing, starting near the anchor
    c_start = int(np.argmin(np.hypot(*(center - anchor).T)))
    c_pts, c_len = spline_resample_closed(np.roll(center, -c_start, axis=0), config.spacing)
    _, c_norm = _tangent_normal(c_pts)
    c_wl, c_wr = _widths(c_pts, c_norm, left_s, right_s)
    c_s = np.arange(len(c_pts)) * (c_len / len(c_pts))
    centerline = np.column_stack([c_s, c_pts, c_wl, c_wr])

    area = _signed_area(xy)
    source_clearance = min(float(polyline_distance(pts, left).min()), float(polyline_distance(pts, right).min()))
    import osqp

    meta = {
        "format_version": FORMAT_VERSION,
        "name": name,
        "length_m": length,
        "num_samples": int(len(s)),
        "driving_direction": "counter-clockwise" if area > 0 else "clockwise",
        "lap_time_s": round(lap_time(v, ds), 4),
        "min_clearance_m": round(float(min(d_left.min(), d_right.min())), 4),
        "min_clearance_left_m": round(float(d_left.min()), 4),
        "min_clearance_right_m": round(float(d_right.min()), 4),
        "min_clearance_source_edges_m": round(source_clearance, 4),
        "max_abs_kappa_radpm": round(float(np.max(np.abs(kappa))), 6),
        "speed_min_mps": round(float(v.min()), 4),
        "speed_max_mps": round(float(v.max()), 4),
        "track_width_min_m": round(float(np.min(c_wl + c_wr)), 4),
        "narrow_qp_nodes": int(race.narrow.sum()),
        "edge_smoothing_max_displacement_m": round(max(disp_l, disp_r), 4),
        "builder": {**dataclasses.asdict(config), "qp_solver": f"osqp {getattr(osqp, '__version__', '?')}"},
        "source": dict(source or {}),
        "provenance": PROVENANCE,
        "files": {
            "raceline": RACELINE_FILE,
            "left_edge": LEFT_EDGE_FILE,
            "right_edge": RIGHT_EDGE_FILE,
            "centerline": CENTERLINE_FILE,
        },
    }
    return BuiltCircuit(raceline, left_s, right_s, centerline, meta)


def write_circuit(folder: str | os.PathLike, built: BuiltCircuit) -> Path:
    """Write the circuit files into ``folder`` (created if needed)."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    fmt_race = ["%.6f", "%.6f", "%.6f", "%.9f", "%.12g", "%.6f", "%.6f", "%.12g"]
    np.savetxt(folder / RACELINE_FILE, built.raceline, delimiter=",", fmt=fmt_race,
               header=",".join(RACELINE_COLUMNS), comments="")
    for edge, fname in ((built.left_edge, LEFT_EDGE_FILE), (built.right_edge, RIGHT_EDGE_FILE)):
        np.savetxt(folder / fname, edge, delimiter=",", fmt="%.6f", header=",".join(EDGE_COLUMNS), comments="")
    np.savetxt(folder / CENTERLINE_FILE, built.centerline, delimiter=",", fmt="%.6f",
               header=",".join(CENTERLINE_COLUMNS), comments="")
    (folder / META_FILE).write_text(json.dumps(built.meta, indent=2) + "\n", encoding="utf-8")
    return folder


def build_track(
    source: str | os.PathLike,
    name: str,
    out_dir: str | os.PathLike | None = None,
    *,
    source_format: str = "edges",
    config: BuildConfig | None = None,
) -> Track:
    """Build a circuit from a CSV file and return it as a :class:`Track`.

    ``source_format`` is ``"edges"`` (``left_x, left_y, right_x, right_y``) or
    ``"centerline"`` (``x_m, y_m, w_tr_right_m, w_tr_left_m``).  When
    ``out_dir`` is given the circuit files are written there and the returned
    Track is loaded back from disk.
    """
    path = Path(source)
    if source_format == "edges":
        left, right = read_edges_csv(path)
    elif source_format == "centerline":
        left, right = read_centerline_csv(path)
    else:
        raise ValueError(f"unknown source format {source_format!r}; use 'edges' or 'centerline'")
    info = {"file": path.name, "sha256": _sha256(path), "format": source_format}
    built = build_from_edges(left, right, name, config, source=info)
    if out_dir is None:
        return built.to_track()
    folder = write_circuit(out_dir, built)
    return Track.load(folder)
