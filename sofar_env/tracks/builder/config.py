"""Parameters of the circuit builder (:class:`BuildConfig`)."""

from __future__ import annotations

import dataclasses
import math
import warnings
from dataclasses import dataclass

__all__ = ["BuildConfig"]


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
        """Raise ValueError for a negative, non-finite or zero-where-positive value; warn for a
        clearance below 1 m."""
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
