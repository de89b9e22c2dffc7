"""Closed-polyline geometry of the circuit builder.

Cleaning, resampling at uniform arc length (linear or through a periodic cubic
spline), periodic smoothing, tangents and normals, and exact distance queries:
point to polyline, ray to polyline, nearest points, and the track widths along
the normals. Every curve here is closed and stored without repeating its first
point.
"""

from __future__ import annotations

import logging

import numpy as np
from scipy import sparse
from scipy.interpolate import CubicSpline
from scipy.sparse.linalg import splu

from ..format import TrackFormatError

__all__ = [
    "clean_closed",
    "signed_area",
    "resample_closed",
    "periodic_smooth",
    "spline_resample_closed",
    "tangent_normal",
    "polyline_distance",
    "ray_polyline_distance",
    "closest_points",
    "edge_widths",
]

logger = logging.getLogger(__name__)


def clean_closed(points: np.ndarray, label: str) -> np.ndarray:
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


def signed_area(points: np.ndarray) -> float:
    """Signed area enclosed by the closed polyline (> 0: counter-clockwise point order) [m^2]."""
    x, y = points[:, 0], points[:, 1]
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def _closed_cumlength(points: np.ndarray) -> np.ndarray:
    """Cumulative arc length at the vertices of the closed polyline, closing segment included."""
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


def tangent_normal(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit tangents (central differences) and left normals of a closed polyline."""
    tangent = np.roll(points, -1, axis=0) - np.roll(points, 1, axis=0)
    tangent /= np.hypot(*tangent.T)[:, None]
    return tangent, np.column_stack([-tangent[:, 1], tangent[:, 0]])


def _segments(poly: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Start points and vectors of the segments of a closed polyline."""
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


def closest_points(points: np.ndarray, poly: np.ndarray, chunk: int = 256) -> np.ndarray:
    """The point of the closed polyline ``poly`` nearest to each of ``points``."""
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


def edge_widths(points: np.ndarray, normal: np.ndarray, left: np.ndarray, right: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distances along +normal to the left edge and along -normal to the right edge."""
    wl = ray_polyline_distance(points, normal, left)
    wr = ray_polyline_distance(points, -normal, right)
    for w, edge, label in ((wl, left, "left"), (wr, right, "right")):
        miss = ~np.isfinite(w)
        if miss.any():
            logger.warning("%d normals miss the %s edge; using the point-to-edge distance", miss.sum(), label)
            w[miss] = polyline_distance(points[miss], edge)
    return wl, wr
