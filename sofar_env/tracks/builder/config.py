"""Parameters of the circuit builder (:class:`BuildConfig`)."""

from __future__ import annotations

import warnings
from dataclasses import dataclass

from ...domains import check_fields, integer, real

__all__ = ["BuildConfig"]


@dataclass(frozen=True)
class BuildConfig:
    """Parameters of the circuit builder."""

    clearance: float = real(2.0, ge=0.0, unit="m")
    """Minimum distance from the raceline to each edge polyline [m]."""
    top_speed: float = real(85.0, gt=0.0, unit="m/s")
    """Speed cap of the speed profile [m/s]."""
    a_lat_max: float = real(15.0, gt=0.0, unit="m/s^2")
    """Lateral acceleration limit, v^2 |kappa| <= a_lat_max [m/s^2]."""
    a_accel_max: float = real(3.0, gt=0.0, unit="m/s^2")
    """Longitudinal acceleration limit [m/s^2]."""
    a_brake_max: float = real(10.0, gt=0.0, unit="m/s^2")
    """Longitudinal deceleration limit (positive number) [m/s^2]."""
    spacing: float = real(1.0, gt=0.0, unit="m")
    """Arc-length spacing of the stored raceline, edges and centreline [m]."""
    qp_spacing: float = real(2.0, gt=0.0, unit="m")
    """Spacing of the reference line inside the minimum-curvature QP [m]."""
    qp_iterations: int = integer(5, ge=1)
    """Number of QP solves, each linearised around the previous raceline [-]."""
    qp_regularization: float = real(1e-8, ge=0.0, unit="1/m^2")
    """Weight of the sum of alpha^2 next to the sum of (h^2 kappa)^2 in the QP [1/m^2]
    (keeps the Hessian positive definite)."""
    raceline_smoothing: float = real(10.0, ge=0.0)
    """Weight of the periodic Whittaker smoother applied to the QP solution before
    it becomes the raceline; removes millimetre ripples inherited from the edge
    data (0 disables) [-]."""
    qp_margin: float = real(0.02, ge=0.0, unit="m")
    """Extra shift margin added to the clearance inside the QP [m]."""
    edge_smoothing: float = real(1.0, ge=0.0, unit="m")
    """Standard deviation of the periodic Gaussian smoothing of the edges [m]."""
    centerline_smoothing: float = real(6.0, ge=0.0, unit="m")
    """Standard deviation of the Gaussian smoothing of the centreline [m]."""
    max_repairs: int = integer(12, ge=0)
    """Maximum number of clearance repair rounds (tighten bounds, re-solve) [-]."""

    def validate(self) -> None:
        """Raise :class:`~sofar_env.errors.ConfigError` (a ValueError) for a field outside its declared domain
        (:mod:`sofar_env.domains`: a wrong type, NaN, inf, a negative or zero-where-positive value); warn for a
        clearance below 1 m. Called by :func:`~sofar_env.tracks.builder.build_track` before any work (the
        builder's internal tests construct deliberately invalid configs, so construction does not check)."""
        check_fields(self, "BuildConfig")
        if self.clearance < 1.0:
            warnings.warn(
                f"clearance {self.clearance} m is below 1.0 m: opponents at +-1 m from the raceline "
                "may leave the track",
                stacklevel=3,
            )
