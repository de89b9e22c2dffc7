"""Parameters of the cars: geometry and actuation limits (:class:`VehicleParams`) and the dynamic plant's
(:class:`DynamicParams`). Values only: the models that use them are :mod:`sofar_env.vehicle` and
:mod:`sofar_env.dynamics`."""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..domains import check_fields, real, reals
from ..errors import ConfigError

__all__ = ["VehicleParams", "AV21", "DynamicParams", "AV21_DYNAMIC"]


@dataclass(frozen=True)
class VehicleParams:
    """Physical parameters and actuation limits (Dallara AV-21 defaults)."""

    wheelbase: float = real(2.9718, gt=0.0, unit="m")
    """L, distance between the axles [m]."""
    lr: float = real(1.2933, gt=0.0, unit="m")
    """l_r, distance from the centre of gravity to the rear axle [m]."""
    a_min: float = real(-10.0, lt=0.0, unit="m/s^2")
    """Strongest braking, lower bound on the longitudinal acceleration [m/s^2]."""
    a_max: float = real(3.0, gt=0.0, unit="m/s^2")
    """Largest longitudinal acceleration [m/s^2]."""
    steer_rate_max: float = real(0.35, gt=0.0, unit="rad/s")
    """Bound on |delta_dot| [rad/s]."""
    steer_max: float = real(0.25, gt=0.0, lt=0.5 * math.pi, unit="rad")
    """Bound on |delta| [rad]."""
    lat_acc_max: float = real(15.0, gt=0.0, unit="m/s^2")
    """Bound on |a_lat| = v * yaw rate [m/s^2] (soft in the MPC)."""
    length: float = real(4.9, gt=0.0, unit="m")
    """Footprint length, bumper to bumper [m]."""
    width: float = real(1.9, gt=0.0, unit="m")
    """Footprint width [m]."""
    cg_to_front: float = real(2.45, gt=0.0, unit="m")
    """Distance from the centre of gravity (the reference point) to the front of the footprint [m]."""

    def __post_init__(self) -> None:
        check_fields(self, "race.vehicle")
        if not self.lr < self.wheelbase:
            raise ConfigError(f"race.vehicle needs 0 < lr < wheelbase, got lr={self.lr}, wheelbase={self.wheelbase}")
        if not self.cg_to_front < self.length:
            raise ConfigError(f"race.vehicle.cg_to_front must lie inside the footprint (< length = {self.length}), "
                              f"got {self.cg_to_front}")

    @property
    def cg_to_rear(self) -> float:
        """Distance from the centre of gravity to the rear of the footprint [m]."""
        return self.length - self.cg_to_front


AV21 = VehicleParams()
"""The default parameter set."""


@dataclass(frozen=True)
class DynamicParams:
    """Dynamic parameters of the AV-21 (geometry and actuator limits are in ``VehicleParams``).

    Mass, inertia, aerodynamics, brake bias and actuator bandwidths from tier4/AWSIM's AV-21R model, tyres and
    the centre-of-gravity height from TUM's AV-21 set. The source of every value, and the alternatives:
    ``docs/decisions/dynamic-plant-parameters.md``.
    """

    mass: float = real(815.11, gt=0.0, unit="kg")
    """m [kg], > 0."""
    yaw_inertia: float = real(800.0, gt=0.0, unit="kg m^2")
    """Iz, yaw moment of inertia [kg m^2], > 0."""
    cg_height: float = real(0.275, ge=0.0, unit="m")
    """h, height of the centre of gravity [m], >= 0."""
    gravity: float = real(9.81, gt=0.0, unit="m/s^2")
    """g [m/s^2]."""
    air_density: float = real(1.225, gt=0.0, unit="kg/m^3")
    """rho, air density [kg/m^3], > 0 (ISA sea level)."""
    drag_area: float = real(0.8581, ge=0.0, unit="m^2")
    """c_d A, drag coefficient times frontal area [m^2], >= 0."""
    lift_area: float = real(1.83, ge=0.0, unit="m^2")
    """c_l A, downforce coefficient times frontal area [m^2], >= 0."""
    aero_front: float = real(0.65 / 1.83, ge=0.0, le=1.0)
    """Share of the downforce on the front axle [-], in [0, 1]."""
    brake_bias_front: float = real(0.54, ge=0.0, le=1.0)
    """Share of the braking force on the front axle [-], in [0, 1]; traction is all on the rear axle."""
    B_f: float = real(10.9, gt=0.0, unit="1/rad")
    """Front lateral stiffness factor B of the Magic Formula [1/rad], > 0, load-independent. Source:
    ``docs/decisions/dynamic-plant-parameters.md``."""
    C_f: float = real(1.603, gt=0.0)
    """Front lateral shape factor C [-], > 0."""
    D_f: float = real(1.389, gt=0.0)
    """Front peak lateral friction coefficient D at mu = 1 [-], > 0 (no load sensitivity). Source:
    ``docs/decisions/dynamic-plant-parameters.md``."""
    E_f: float = real(-1.409, le=1.0)
    """Front lateral curvature factor E [-], <= 1."""
    B_r: float = real(10.9, gt=0.0, unit="1/rad")
    """Rear lateral stiffness factor B [1/rad], > 0."""
    C_r: float = real(1.603, gt=0.0)
    """Rear lateral shape factor C [-], > 0."""
    D_r: float = real(1.389, gt=0.0)
    """Rear peak lateral friction coefficient D at mu = 1 [-], > 0."""
    E_r: float = real(-1.409, le=1.0)
    """Rear lateral curvature factor E [-], <= 1."""
    D_x: float = real(1.597, gt=0.0)
    """Peak longitudinal friction coefficient at mu = 1 [-], > 0: the friction ellipse's longitudinal
    semi-axis."""
    tau_steer: float = real(1.0 / (2.0 * math.pi * 3.0), gt=0.0, unit="s")
    """Time constant of the steering's first-order lag [s], > 0 (no pure delay). Source:
    ``docs/decisions/dynamic-plant-parameters.md``."""
    tau_accel: float = real(0.1, gt=0.0, unit="s")
    """Time constant of the powertrain / brake first-order lag [s], > 0. Source: ``docs/decisions/dynamic-plant-parameters.md``."""
    v_blend_low: float = real(3.0, ge=0.0, unit="m/s")
    """Below this forward speed the model is purely kinematic [m/s]."""
    v_blend_high: float = real(6.0, gt=0.0, unit="m/s")
    """Above this forward speed the model is purely dynamic [m/s]."""
    v_floor: float = real(1.0, gt=0.0, unit="m/s")
    """Floor on vx in the slip angles [m/s] (only matters where the kinematic model rules)."""
    tau_kinematic: float = real(0.1, gt=0.0, unit="s")
    """Relaxation time of the low-speed model onto the kinematic manifold [s]."""
    yaw_rate_gain: float = real(0.0, ge=0.0)
    """Loop gain K [-] of the car's low-level yaw-rate controller; 0 (the default) switches it off.
    With K > 0 the steering servo is not aimed at the commanded angle ``delta_cmd`` itself but at
    ``delta_cmd + K L / max(vx, v_blend_high) (r_ref - r)``, clipped to +-steer_max, where
    ``r_ref = v cos(beta) tan(delta_cmd) / L`` (``beta = atan(lr/L tan delta_cmd)``, ``v = |(vx, vy)|``)
    is the yaw rate the kinematic bicycle has at the commanded angle. ``K L / vx`` makes K the
    dimensionless loop gain at the kinematic yaw gain ``vx / L``, >= 0. Why: ``docs/decisions/dynamic-plant-parameters.md``."""
    mu_range: tuple[float, float] = reals((0.8, 1.0), size=2, gt=0.0, ordered=True)
    """Range [-] from which a world should draw the per-episode friction factor mu (uniform), > 0, ordered;
    mu scales the tyres' peak friction coefficients. Decision: ``docs/decisions/dynamic-plant-parameters.md``."""

    def __post_init__(self) -> None:
        check_fields(self, "race.dynamic")
        if not self.v_blend_low < self.v_blend_high:
            raise ConfigError(f"race.dynamic needs v_blend_low < v_blend_high, got {self.v_blend_low} and "
                              f"{self.v_blend_high}")


AV21_DYNAMIC = DynamicParams()
"""The default dynamic parameter set."""
