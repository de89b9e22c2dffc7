"""Edge preparation and the centreline: the first stage of the builder.

The two source edges are put in the driving direction implied by their
left/right labels, resampled at uniform arc length and lightly smoothed (a
periodic Gaussian that moves points by centimetres). The centreline is found by
pairing each left-edge point with its nearest right-edge point, then re-centred
between the edges along its own normals; it is the reference line the
minimum-curvature QP starts from.
"""

from __future__ import annotations

import logging

import numpy as np
from scipy.ndimage import gaussian_filter1d

from .config import BuildConfig
from .polyline import (
    closest_points,
    edge_widths,
    polyline_distance,
    resample_closed,
    signed_area,
    spline_resample_closed,
    tangent_normal,
)

__all__ = ["orient_edges", "prepare_edge", "centerline"]

logger = logging.getLogger(__name__)


def orient_edges(left: np.ndarray, right: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Order both edges in the driving direction implied by the left/right labels."""
    a_left, a_right = signed_area(left), signed_area(right)
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


def prepare_edge(points: np.ndarray, config: BuildConfig) -> tuple[np.ndarray, float]:
    """Uniformly resampled, lightly smoothed closed edge and the max smoothing displacement."""
    res = resample_closed(points, config.spacing)
    if config.edge_smoothing <= 0:
        return res, 0.0
    sigma = config.edge_smoothing / config.spacing
    smooth = np.column_stack([gaussian_filter1d(res[:, k], sigma, mode="wrap") for k in range(2)])
    return smooth, float(np.max(polyline_distance(smooth, points)))


def centerline(left: np.ndarray, right: np.ndarray, config: BuildConfig) -> np.ndarray:
    """Closed centreline at ``qp_spacing``, equidistant from the edges along its normals."""
    mid = 0.5 * (left + closest_points(left, right))
    sigma = config.centerline_smoothing / config.qp_spacing
    center = resample_closed(mid, config.qp_spacing)
    for _ in range(4):
        center = np.column_stack([gaussian_filter1d(center[:, k], sigma, mode="wrap") for k in range(2)])
        center, _ = spline_resample_closed(center, config.qp_spacing)
        _, normal = tangent_normal(center)
        wl, wr = edge_widths(center, normal, left, right)
        center = center + (0.5 * (wl - wr))[:, None] * normal
        center, _ = spline_resample_closed(center, config.qp_spacing)
    return center
