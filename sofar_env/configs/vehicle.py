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

    The full AV-21 set is confidential; the public sets disagree. Mass, inertia, aerodynamics,
    brake bias and actuator bandwidths are taken from one source, the AV-21R model of
    tier4/AWSIM (``docs/RacingSim/VehicleDynamics``), the only public set whose axle distances
    (lf 1.6785 m, lr 1.2933 m) match the kinematic model's. AWSIM publishes no tyre or
    CoG-height data; those come from TUM's AV-21 set ("TUMRT": the file
    ``data/vehicle_params/params_dallaraAV21.yml`` of TUMRT/sampling_based_3D_local_planning).
    "Open-Car-Dynamics" is TUMFTM/Open-Car-Dynamics' generic single-seater configuration
    (``OCD_Vehicle_RWD_LSD__PT1__SINGLE_TRACK__MF_SIMPLE__DEFAULT.json``), quoted for comparison.
    """

    mass: float = real(815.11, gt=0.0, unit="kg")
    """m [kg]. AWSIM AV-21R (TUMRT: 750 kg; AWSIM chosen for consistency with lf/lr, Iz)."""
    yaw_inertia: float = real(800.0, gt=0.0, unit="kg m^2")
    """Iz [kg m^2]. AWSIM AV-21R (the Open-Car-Dynamics generic single-seater uses 1000)."""
    cg_height: float = real(0.275, ge=0.0, unit="m")
    """h, height of the centre of gravity [m]. TUMRT AV-21 set (AWSIM gives none)."""
    gravity: float = real(9.81, gt=0.0, unit="m/s^2")
    """g [m/s^2]."""
    air_density: float = real(1.225, gt=0.0, unit="kg/m^3")
    """rho [kg/m^3], ISA sea level (also TUMRT's value)."""
    drag_area: float = real(0.8581, ge=0.0, unit="m^2")
    """c_d A [m^2]: AWSIM C_d 0.8581 with frontal area 1.0 m^2 (TUMRT: 0.725)."""
    lift_area: float = real(1.83, ge=0.0, unit="m^2")
    """c_l A [m^2], downforce: AWSIM C_lf + C_lr = 0.65 + 1.18 with A = 1.0 m^2 (TUMRT: 1.556)."""
    aero_front: float = real(0.65 / 1.83, ge=0.0, le=1.0)
    """Share of the downforce on the front axle [-]: AWSIM C_lf / (C_lf + C_lr) = 0.355."""
    brake_bias_front: float = real(0.54, ge=0.0, le=1.0)
    """Share of the braking force on the front axle [-]. AWSIM (54 % front); traction is all on
    the rear axle (AWSIM: rear differential, rear-wheel drive)."""
    B_f: float = real(10.9, gt=0.0, unit="1/rad")
    """Front lateral stiffness factor [1/rad]. From TUMRT's Magic-Formula 5.2 set at the tyre's
    nominal load N0 = 3114 N: B = K_y / (C D Fz) with K_y = p_Ky1 N0 sin(2 atan(Fz / (p_Ky2 N0)))
    (p_Ky1 = 53.05, p_Ky2 = 4.1265); B varies only 10.82-10.90 over the static wheel loads, so it
    is taken load-independent (Open-Car-Dynamics' generic simple MF uses 10)."""
    C_f: float = real(1.603, gt=0.0)
    """Front lateral shape factor [-]: TUMRT p_Cy1 (Open-Car-Dynamics: 1.6)."""
    D_f: float = real(1.389, gt=0.0)
    """Front peak lateral friction coefficient at mu = 1 [-]: TUMRT p_Dy1 lambda_muy =
    1.654 x 0.84 at the nominal load (its load sensitivity p_Dy2 is neglected). Chosen over
    Open-Car-Dynamics' generic 1.7 because it is fitted to the AV-21; it is the conservative one."""
    E_f: float = real(-1.409, le=1.0)
    """Front lateral curvature factor [-]: TUMRT p_Ey1 (peak at about 5.8 deg of slip)."""
    B_r: float = real(10.9, gt=0.0, unit="1/rad")
    """Rear lateral stiffness factor [1/rad]; same tyre as the front (TUMRT uses one set)."""
    C_r: float = real(1.603, gt=0.0)
    """Rear lateral shape factor [-]: TUMRT p_Cy1."""
    D_r: float = real(1.389, gt=0.0)
    """Rear peak lateral friction coefficient at mu = 1 [-]: TUMRT p_Dy1 lambda_muy."""
    E_r: float = real(-1.409, le=1.0)
    """Rear lateral curvature factor [-]: TUMRT p_Ey1."""
    D_x: float = real(1.597, gt=0.0)
    """Peak longitudinal friction coefficient at mu = 1 [-], the friction ellipse's
    longitudinal semi-axis: TUMRT p_Dx1 lambda_mux = 1.7168 x 0.93."""
    tau_steer: float = real(1.0 / (2.0 * math.pi * 3.0), gt=0.0, unit="s")
    """Steering first-order lag [s]: AWSIM's steering-motor bandwidth 3 Hz, 1/(2 pi 3 Hz) =
    0.053 s (AWSIM's 0.04 s pure delay is not modelled; Open-Car-Dynamics uses a 0.06 s PT1)."""
    tau_accel: float = real(0.1, gt=0.0, unit="s")
    """Powertrain/brake first-order lag [s]. AWSIM's brake-by-wire has a 0.04 s delay plus a
    5 Hz bandwidth (0.032 s), about 0.07 s lumped; no public engine-torque figure exists and a
    combustion engine through a gearbox responds more slowly than the brakes, hence 0.1 s."""
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
    dimensionless loop gain at the kinematic yaw gain ``vx / L``. The loop is what makes a car that
    slides behave like the kinematic bicycle a kinematic MPC plans with: it adds yaw damping and
    takes out most of the under- or oversteer, as the low-level lateral controllers of the
    Indy Autonomous Challenge stacks do below their trajectory planners."""
    mu_range: tuple[float, float] = reals((0.8, 1.0), size=2, gt=0.0, ordered=True)
    """Range [-] from which a world should draw the per-episode friction factor mu (uniform).
    The nominal tyre set (mu = 1) already carries TUM's fitted scaling lambda_muy = 0.84 of a
    dry, rubbered-in track; 0.8 represents a cold or green track. Lower values (wet) are outside
    what slick tyres are raced on."""

    def __post_init__(self) -> None:
        check_fields(self, "race.dynamic")
        if not self.v_blend_low < self.v_blend_high:
            raise ConfigError(f"race.dynamic needs v_blend_low < v_blend_high, got {self.v_blend_low} and "
                              f"{self.v_blend_high}")


AV21_DYNAMIC = DynamicParams()
"""The default dynamic parameter set."""
