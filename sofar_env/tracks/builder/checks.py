"""Checks of the builder's input geometry, run before any of the expensive stages.

An edge must be a closed curve (its last point near its first, compared with the
spacing of its points) that does not cross itself, and the two edges must neither
cross nor touch each other. Input that breaks one of these rules would otherwise
make the raceline QP run for minutes or produce a folded circuit; here it fails at
once with a :class:`~sofar_env.tracks.TrackFormatError` naming the input and the
problem. The tests are exact (segment against segment), in O(n m) time on arrays
(a fraction of a second for edges of a few thousand points).
"""

from __future__ import annotations

import numpy as np

from ..format import TrackFormatError
from .polyline import polyline_distance

__all__ = ["MAX_CLOSING_GAP", "MIN_EDGE_DISTANCE", "check_closed", "check_simple", "check_apart", "check_edges"]

MAX_CLOSING_GAP = 10.0
"""Largest accepted distance from the last point of an edge to its first, in units of the
median distance between consecutive points [-] (the shipped inputs have at most 2)."""

MIN_EDGE_DISTANCE = 0.01
"""Smallest accepted distance between the left and the right edge [m]."""


def check_closed(points: np.ndarray, label: str) -> None:
    """Raise when the edge ``points`` do not form a closed loop.

    The closing segment (last point back to the first) must be at most
    :data:`MAX_CLOSING_GAP` times the median point spacing long.
    """
    steps = np.hypot(*np.diff(points, axis=0).T)
    spacing = float(np.median(steps))
    gap = float(np.hypot(*(points[-1] - points[0])))
    if gap > MAX_CLOSING_GAP * spacing:
        raise TrackFormatError(
            f"{label}: the edge is not closed: its last point is {gap:.1f} m from its first, "
            f"{gap / spacing:.0f} times the median point spacing of {spacing:.2f} m "
            "(an edge must go all the way round the circuit)"
        )


def _crossings(a: np.ndarray, b: np.ndarray, chunk: int = 256) -> tuple[int, int] | None:
    """First pair (i, j) of proper crossings of segment i of closed polyline ``a`` and
    segment j of closed polyline ``b``, or None.

    A proper crossing has the end points of each segment strictly on both sides of the
    other one, so segments sharing an end point (neighbours along one polyline) never count.
    """
    pa, va = a, np.roll(a, -1, axis=0) - a
    pb, vb = b, np.roll(b, -1, axis=0) - b
    for lo in range(0, len(a), chunk):
        p, v = pa[lo : lo + chunk, None, :], va[lo : lo + chunk, None, :]
        wx, wy = pb[None, :, 0] - p[..., 0], pb[None, :, 1] - p[..., 1]  # b start - a start
        # sides of b's end points relative to segment a, and of a's end points relative to b
        o1 = v[..., 0] * wy - v[..., 1] * wx
        o2 = v[..., 0] * (wy + vb[None, :, 1]) - v[..., 1] * (wx + vb[None, :, 0])
        o3 = vb[None, :, 0] * (-wy) - vb[None, :, 1] * (-wx)
        o4 = vb[None, :, 0] * (v[..., 1] - wy) - vb[None, :, 1] * (v[..., 0] - wx)
        hit = (o1 * o2 < 0.0) & (o3 * o4 < 0.0)
        if hit.any():
            i, j = np.argwhere(hit)[0]
            return lo + int(i), int(j)
    return None


def check_simple(points: np.ndarray, label: str) -> None:
    """Raise when the closed edge ``points`` crosses itself (a figure-eight, a loop)."""
    hit = _crossings(points, points)
    if hit is not None:
        i, j = sorted(hit)
        x, y = points[i]
        raise TrackFormatError(
            f"{label}: the edge crosses itself (segment {i} near ({x:.1f}, {y:.1f}) m crosses "
            f"segment {j}); an edge must be a simple closed curve"
        )


def check_apart(left: np.ndarray, right: np.ndarray, label: str) -> None:
    """Raise when the left and the right edge cross or come closer than :data:`MIN_EDGE_DISTANCE`."""
    hit = _crossings(left, right)
    if hit is not None:
        x, y = left[hit[0]]
        raise TrackFormatError(
            f"{label}: the left and right edges cross near ({x:.1f}, {y:.1f}) m; "
            "the track must have a positive width everywhere"
        )
    dist = polyline_distance(left, right)
    k = int(np.argmin(dist))
    if dist[k] < MIN_EDGE_DISTANCE:
        x, y = left[k]
        raise TrackFormatError(
            f"{label}: zero track width: the left and right edges touch or coincide near "
            f"({x:.1f}, {y:.1f}) m (distance {dist[k]:.3g} m); "
            "the track must have a positive width everywhere"
        )


def check_edges(left: np.ndarray, right: np.ndarray, label: str) -> None:
    """All the checks of this module on the two cleaned source edges."""
    for points, side in ((left, "left edge"), (right, "right edge")):
        check_closed(points, f"{label} ({side})")
        check_simple(points, f"{label} ({side})")
    check_apart(left, right, label)
