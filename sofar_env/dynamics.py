"""Dynamic single-track (bicycle) model of the Dallara AV-21 with Pacejka tyres, and its plant.

The kinematic model of :mod:`sofar_env.vehicle` assumes the tyres never slide. This module
adds the model an "interactive" race world needs when cars can slide: body-frame velocities,
yaw inertia, per-axle Magic-Formula lateral forces on loads that change with downforce and
longitudinal load transfer, a friction ellipse that couples braking and cornering, a friction
coefficient ``mu`` drawn per episode, and first-order actuator lags. The right-hand side is
written **once** over an ``ops`` namespace (``math`` for the plant, :mod:`casadi` for
symbolic use), as in :mod:`sofar_env.vehicle`.

State (9) and input (2)
-----------------------
``(x, y, psi, vx, vy, r, delta, delta_cmd, a)``: position [m], yaw [rad], body-frame velocity
at the centre of gravity, forward and left [m/s], yaw rate [rad/s], road-wheel steering angle
[rad], commanded steering angle [rad], longitudinal acceleration delivered by the
powertrain/brakes [m/s^2]. The input is the kinematic plant's, ``(a_cmd [m/s^2],
delta_dot_cmd [rad/s])``; the limits ``a_min, a_max, steer_max, steer_rate_max``, the
wheelbase and ``lr`` are those of :class:`sofar_env.vehicle.VehicleParams`, so both plants
share them (``lf = wheelbase - lr``).

Equations (SI units, g the gravitational acceleration)
------------------------------------------------------
Kinematics: ``x' = vx cos psi - vy sin psi``, ``y' = vx sin psi + vy cos psi``, ``psi' = r``.

Actuators: ``delta_cmd' = delta_dot_cmd`` (clipped to +-steer_rate_max; delta_cmd clipped to
+-steer_max after every sub-step), ``delta' = (delta_cmd - delta) / tau_steer``,
``a' = (a_cmd - a) / tau_accel`` with ``a_cmd`` clipped to ``[a_min, a_max]``.

Aerodynamics: dynamic pressure ``q = rho vx^2 / 2``; drag ``F_D = q cdA``; downforce
``F_L = q clA``, a share ``aero_front`` on the front axle.

Loads: ``Fz_f = m g lr/L + aero_front F_L - m a h/L``, ``Fz_r = m g lf/L + (1 - aero_front)
F_L + m a h/L`` (both floored at 0). The load transfer uses the actuator state ``a``, the
acceleration the car is asked to deliver, which avoids an algebraic loop through the forces.

Longitudinal forces: ``a`` is the *net* acceleration along the body x axis, the quantity the
kinematic plant integrates as ``v' = a`` and the kinematic MPC plans with; the tyres must
therefore deliver ``F_x = m a + F_D``. Braking (``F_x < 0``) is split ``brake_bias_front``
to the front axle, traction goes to the rear (rear-wheel drive).

Friction ellipse, longitudinal priority, per axle ``i``: ``eta_i = clip(F_xi / (mu Dx
Fz_i), -1, 1)``, delivered ``F_xi = eta_i mu Dx Fz_i`` and ``F_yi = mu D_i Fz_i
sqrt(1 - eta_i^2) sin(C_i atan(B_i alpha_i - E_i (B_i alpha_i - atan(B_i alpha_i))))``, so
``(F_x/(mu Dx Fz))^2 + (F_y/(mu D Fz))^2 <= 1``: braking or driving at the limit leaves no
lateral grip on that axle. Slip angles ``alpha_f = delta - atan2(vy + lf r, max(vx, v_floor))``,
``alpha_r = -atan2(vy - lr r, max(vx, v_floor))``.

Body-frame dynamics: ``m (vx' - vy r) = F_xf cos delta - F_yf sin delta + F_xr - F_D``,
``m (vy' + vx r) = F_xf sin delta + F_yf cos delta + F_yr``,
``Iz r' = lf (F_xf sin delta + F_yf cos delta) - lr F_yr``.

Low speed: the rates of ``(vx, vy, r)`` blend, with weight ``w = smoothstep((vx -
v_blend_low) / (v_blend_high - v_blend_low))``, into those of the kinematic bicycle of
:func:`sofar_env.vehicle.cartesian_rhs` driven by the *actual* delta. With ``beta =
atan(lr/L tan delta)`` that model's manifold is ``vy = vx tan beta``, ``r = vx tan(delta)/L``;
its rates (:func:`_kinematic_rates`) keep the state on the manifold with speed ``v =
|(vx, vy)|`` obeying ``v' = a`` and pull it back onto it with time constant
``tau_kinematic``. On the manifold the kinematics above *are* the kinematic model's
(``x' = v cos(psi + beta)``, ``psi' = v cos(beta) tan(delta)/L``), so below ``v_blend_low``
the plant reproduces it and is well-posed at standstill. The car does not reverse: the plant
stops it (``vx = vy = r = 0``) when a sub-step would end with ``vx < 0``.

Not modelled: engine power (``a_max`` bounds the net acceleration, as in the kinematic plant),
the actuators' pure delays, tyre load sensitivity, lateral load transfer and roll, wheel spin
and lock-up (longitudinal slip), the pitch moment of drag. With these parameters the car is
close to neutral under hard braking at speed (the braking load transfer offsets the
rear-biased downforce), so steering past the grip limit while braking hard can spin it.
"""

from __future__ import annotations

import math
from typing import Any, Sequence

import numpy as np

from .configs.vehicle import AV21_DYNAMIC, DynamicParams
from .vehicle import AV21, VehicleParams, rk4_step

__all__ = ["STATE_NAMES", "DynamicParams", "AV21_DYNAMIC", "pacejka", "dynamic_rhs", "casadi_dynamics", "DynamicPlant"]

STATE_NAMES = ("x", "y", "psi", "vx", "vy", "r", "delta", "delta_cmd", "a")
"""Names of the 9 state components, in order."""


# --------------------------------------------------------------------------------------
# The model, written once over an ``ops`` namespace (math or casadi).
# --------------------------------------------------------------------------------------


def pacejka(alpha: Any, B: float, C: float, E: float, ops: Any = math) -> Any:
    """Normalised Magic Formula sin(C atan(B alpha - E (B alpha - atan(B alpha)))) [-]; peak 1."""
    ba = B * alpha
    return ops.sin(C * ops.atan(ba - E * (ba - ops.atan(ba))))


def _minmax(ops: Any):
    """(min, max) of two scalars for ``ops``: Python's builtins for math, else ``ops.fmin, ops.fmax``."""
    if ops is math:
        return min, max
    return ops.fmin, ops.fmax


def _dynamic_rates(vx: Any, vy: Any, r: Any, delta: Any, a: Any, mu: Any, p: DynamicParams,
                   veh: VehicleParams, ops: Any) -> tuple:
    """(vx', vy', r') of the dynamic single track: aero, loads, friction ellipse, tyres, Newton-Euler."""
    fmin, fmax = _minmax(ops)
    L, lr = veh.wheelbase, veh.lr
    lf = L - lr
    m = p.mass
    cos_d, sin_d = ops.cos(delta), ops.sin(delta)
    q = 0.5 * p.air_density * vx * vx
    drag, lift = q * p.drag_area, q * p.lift_area
    transfer = m * a * p.cg_height / L
    fz_f = fmax(m * p.gravity * lr / L + p.aero_front * lift - transfer, 0.0)
    fz_r = fmax(m * p.gravity * lf / L + (1.0 - p.aero_front) * lift + transfer, 0.0)
    fx = m * a + drag
    fx_f_demand = p.brake_bias_front * fmin(fx, 0.0)
    cap_f, cap_r = mu * p.D_x * fz_f, mu * p.D_x * fz_r
    ratio_f = fmin(fmax(fx_f_demand / fmax(cap_f, 1.0), -1.0), 1.0)
    ratio_r = fmin(fmax((fx - fx_f_demand) / fmax(cap_r, 1.0), -1.0), 1.0)
    vx_slip = fmax(vx, p.v_floor)
    alpha_f = delta - ops.atan2(vy + lf * r, vx_slip)
    alpha_r = -ops.atan2(vy - lr * r, vx_slip)
    # The 1e-12 keeps the square root differentiable for CasADi at a saturated axle.
    fy_f = (mu * p.D_f * fz_f * ops.sqrt(1.0 - ratio_f * ratio_f + 1e-12)
            * pacejka(alpha_f, p.B_f, p.C_f, p.E_f, ops))
    fy_r = (mu * p.D_r * fz_r * ops.sqrt(1.0 - ratio_r * ratio_r + 1e-12)
            * pacejka(alpha_r, p.B_r, p.C_r, p.E_r, ops))
    fx_f, fx_r = ratio_f * cap_f, ratio_r * cap_r
    front_lat = fx_f * sin_d + fy_f * cos_d
    return ((fx_f * cos_d - fy_f * sin_d + fx_r - drag) / m + vy * r,
            (front_lat + fy_r) / m - vx * r,
            (lf * front_lat - lr * fy_r) / p.yaw_inertia)


def _kinematic_rates(vx: Any, vy: Any, r: Any, delta: Any, delta_dot: Any, a: Any, p: DynamicParams,
                     veh: VehicleParams, ops: Any) -> tuple:
    """(vx', vy', r') of the kinematic bicycle, held on its manifold vy = vx tan(beta), r = vx tan(delta)/L.

    On the manifold ``vx = v cos(beta)``, so ``vx' = a cos(beta) - vx tan(beta) beta'`` makes the
    speed ``v = vx / cos(beta)`` obey ``v' = a``; vy and r follow the time derivatives of their
    manifold values plus a relaxation ``(target - state) / tau_kinematic``. Polynomial in vx: well
    defined at (and, inside an RK4 stage, slightly below) standstill.
    """
    L = veh.wheelbase
    k = veh.lr / L
    cos_d, sin_d = ops.cos(delta), ops.sin(delta)
    tan_d = sin_d / cos_d
    tan_b = k * tan_d  # beta = atan(lr / L tan(delta))
    cos_b2 = 1.0 / (1.0 + tan_b * tan_b)
    beta_dot = k * delta_dot / (cos_d * cos_d + k * k * sin_d * sin_d)
    vx_dot = a * ops.sqrt(cos_b2) - vx * tan_b * beta_dot
    vy_target, r_target = vx * tan_b, vx * tan_d / L
    vy_dot = vx_dot * tan_b + vx * beta_dot / cos_b2 + (vy_target - vy) / p.tau_kinematic
    r_dot = (vx_dot * tan_d + vx * delta_dot / (cos_d * cos_d)) / L + (r_target - r) / p.tau_kinematic
    return vx_dot, vy_dot, r_dot


def dynamic_rhs(x: Sequence[Any], u: Sequence[Any], mu: Any, p: DynamicParams = AV21_DYNAMIC,
                veh: VehicleParams = AV21, ops: Any = math) -> list:
    """Time derivative of the 9-state (module docstring) under the *clipped* input (a_cmd, delta_dot_cmd).

    ``mu`` scales every friction coefficient (1 = nominal). Evaluates with ``ops=math`` on floats
    and with ``ops=casadi`` on symbols. On floats, a part whose blend weight is exactly 0 is not
    evaluated (the sum would add an exact 0.0).
    """
    fmin, fmax = _minmax(ops)
    _, _, psi, vx, vy, r, delta, delta_cmd, a = x
    a_cmd, delta_dot_cmd = u
    target = delta_cmd
    if p.yaw_rate_gain > 0.0:
        L = veh.wheelbase
        tan_c = ops.tan(delta_cmd)
        tan_b = veh.lr / L * tan_c
        r_ref = ops.sqrt(vx * vx + vy * vy) * tan_c / (L * ops.sqrt(1.0 + tan_b * tan_b))  # v cos(beta) tan/L
        gain = p.yaw_rate_gain * L / fmax(vx, p.v_blend_high)
        target = fmin(fmax(delta_cmd + gain * (r_ref - r), -veh.steer_max), veh.steer_max)
    delta_dot = (target - delta) / p.tau_steer
    t = fmin(fmax((vx - p.v_blend_low) / (p.v_blend_high - p.v_blend_low), 0.0), 1.0)
    if isinstance(t, float) and t >= 1.0:
        vx_dot, vy_dot, r_dot = _dynamic_rates(vx, vy, r, delta, a, mu, p, veh, ops)
    elif isinstance(t, float) and t <= 0.0:
        vx_dot, vy_dot, r_dot = _kinematic_rates(vx, vy, r, delta, delta_dot, a, p, veh, ops)
    else:
        w = t * t * (3.0 - 2.0 * t)  # smoothstep
        dyn = _dynamic_rates(vx, vy, r, delta, a, mu, p, veh, ops)
        kin = _kinematic_rates(vx, vy, r, delta, delta_dot, a, p, veh, ops)
        vx_dot, vy_dot, r_dot = (w * d + (1.0 - w) * k for d, k in zip(dyn, kin))
    cos_psi, sin_psi = ops.cos(psi), ops.sin(psi)
    return [
        vx * cos_psi - vy * sin_psi,
        vx * sin_psi + vy * cos_psi,
        r,
        vx_dot,
        vy_dot,
        r_dot,
        delta_dot,
        delta_dot_cmd,
        (a_cmd - a) / p.tau_accel,
    ]


def casadi_dynamics(p: DynamicParams = AV21_DYNAMIC, veh: VehicleParams = AV21, dt: float | None = None,
                    substeps: int = 1):
    """CasADi function of the dynamic model: ``f(x[9], u[2], mu) -> x_dot[9]`` (``dt=None``), or
    ``F(x[9], u[2], mu) -> x_next[9]``, RK4 over ``dt`` [s] in ``substeps`` steps (no clipping)."""
    import casadi as ca

    x = ca.SX.sym("x", 9)
    u = ca.SX.sym("u", 2)
    mu = ca.SX.sym("mu")
    xs = [x[i] for i in range(9)]
    us = [u[0], u[1]]
    if dt is None:
        out = dynamic_rhs(xs, us, mu, p, veh, ca)
        return ca.Function("dynamic_ode", [x, u, mu], [ca.vertcat(*out)], ["x", "u", "mu"], ["x_dot"])
    out = rk4_step(lambda xx, uu: dynamic_rhs(xx, uu, mu, p, veh, ca), xs, us, dt, substeps)
    return ca.Function("dynamic_rk4", [x, u, mu], [ca.vertcat(*out)], ["x", "u", "mu"], ["x_next"])


# --------------------------------------------------------------------------------------
# Plant
# --------------------------------------------------------------------------------------


class DynamicPlant:
    """Numeric plant of the dynamic model: RK4 sub-steps of :func:`dynamic_rhs` on Python floats.

    Input handling matches :class:`sofar_env.vehicle.Plant`: ``a_cmd`` is clipped to
    ``[a_min, a_max]`` and ``delta_dot_cmd`` to ``+-steer_rate_max``, held over ``dt``; after every
    sub-step ``delta_cmd`` is clipped to ``+-steer_max``. A sub-step that would end with ``vx < 0``
    means the car came to rest within it: the pose stays at the sub-step's start and ``vx, vy, r``
    are zeroed (the lost travel is below ``|a_min| h^2 / 2``, 3 mm), so a braked car at rest
    stays at rest instead of creeping backwards inside the RK4 stages.

    ``substeps`` defaults to 4 (h = 25 ms at dt = 0.1 s). The Jacobian eigenvalues over
    vx in [3, 90] m/s, delta up to steer_max, a in {a_min, 0, a_max} and mu in {0.8, 1} are largest
    in modulus, about 90 /s (real), at 5-6 m/s, where the blend has just handed over to the
    tyres and the yaw/side-slip modes scale like cornering stiffness / (m vx); at 90 m/s the
    largest is the steering lag, 1/tau_steer = 19 /s, the tyre modes about 11 /s. RK4 is stable
    for |lambda h| < 2.78: 4 sub-steps give |lambda h| <= 2.25 everywhere (3 do not: a 5.5 m/s
    turn then drifts 0.7 m from a fine reference within 3 s). At 90 m/s in a 22 m/s^2 turn the
    position differs by 2e-6 m after 3 s from a 64-sub-step reference. Re-check if you change
    tyre stiffness, mass, inertia or the blend speeds.
    """

    state_size = 9

    def __init__(self, params: DynamicParams = AV21_DYNAMIC, vehicle: VehicleParams = AV21, dt: float = 0.1,
                 substeps: int = 4):
        if dt <= 0 or substeps < 1:
            raise ValueError("dt must be positive and substeps >= 1")
        self.params = params
        self.vehicle = vehicle
        self.dt = float(dt)
        """Control period [s]."""
        self.substeps = int(substeps)

    def initial_state(self, x: float, y: float, psi: float, v: float, delta: float = 0.0) -> np.ndarray:
        """State at pose (x, y, psi), forward speed v >= 0 [m/s], steering delta [rad], at rest laterally."""
        if v < 0.0:
            raise ValueError(f"speed must be non-negative, got {v}")
        d = min(max(float(delta), -self.vehicle.steer_max), self.vehicle.steer_max)
        return np.array([x, y, psi, v, 0.0, 0.0, d, d, 0.0], dtype=float)

    def step(self, state: Sequence[float], u: Sequence[float], mu: float = 1.0) -> np.ndarray:
        """State after one control period with input ``u = (a_cmd, delta_dot_cmd)`` held, friction factor ``mu``."""
        veh = self.vehicle
        a_cmd, dd = float(u[0]), float(u[1])
        for name, value in (("a_cmd", a_cmd), ("delta_dot_cmd", dd), ("mu", float(mu))):
            if not math.isfinite(value):
                raise ValueError(f"non-finite {name}: {value!r}")
        mu = float(mu)
        if mu <= 0.0:
            raise ValueError(f"mu must be positive, got {mu}")
        if len(state) != 9:
            raise ValueError(f"state must have 9 components, got {len(state)}")
        uc = (min(max(a_cmd, veh.a_min), veh.a_max), min(max(dd, -veh.steer_rate_max), veh.steer_rate_max))
        p, steer_max = self.params, veh.steer_max
        h = self.dt / self.substeps

        def rhs(xx, uu):
            return dynamic_rhs(xx, uu, mu, p, veh, math)

        xs = [float(c) for c in state]
        for _ in range(self.substeps):
            new = rk4_step(rhs, xs, uc, h)
            new[7] = min(max(new[7], -steer_max), steer_max)
            if new[3] < 0.0:  # came to rest within the sub-step: stay put, never roll backwards
                new[:6] = xs[0], xs[1], xs[2], 0.0, 0.0, 0.0
            xs = new
        return np.array(xs)

    @staticmethod
    def kinematic_view(state: Sequence[float]) -> np.ndarray:
        """(x, y, psi, v, delta) as a kinematic MPC sees it: v = |(vx, vy)|, delta = delta_cmd."""
        return np.array([state[0], state[1], state[2], math.hypot(state[3], state[4]), state[7]])

    @staticmethod
    def lateral_acceleration(state: Sequence[float]) -> float:
        """Speed times yaw rate, v r [m/s^2], the definition of ``vehicle.lateral_acceleration``;
        it equals the centripetal acceleration in steady cornering."""
        return math.hypot(state[3], state[4]) * state[5]
