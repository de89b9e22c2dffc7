"""Vehicle model of the Dallara AV-21: parameters, kinematic bicycle with slip, plant.

The kinematic bicycle referenced at the centre of gravity with side slip
(paper appendix) is written **once**, as functions over an ``ops`` namespace
(``sin``, ``cos``, ``tan``, ``atan``). Passing :mod:`casadi` builds the symbolic
model used by the MPC; passing :mod:`math` evaluates the very same equations on
Python floats. The two therefore cannot drift apart. (The plant's RK4 step is that
evaluation written out for speed; a test checks it against the generic form bit for bit.)

States and inputs
-----------------
Cartesian plant state ``(x, y, psi, v, delta)``: position [m], yaw [rad],
speed [m/s], steering angle [rad]. Frenet state ``(s, n, e, v, delta)``: arc
length along the reference line [m], lateral offset (+ left) [m], heading error
[rad], speed, steering. Input ``(a, delta_dot)``: longitudinal acceleration
[m/s^2] and steering rate [rad/s].
"""

from __future__ import annotations

import math
from typing import Any, Callable, Sequence

import numpy as np

from ._jit import kernel
from .configs.vehicle import AV21, VehicleParams

__all__ = [
    "VehicleParams",
    "AV21",
    "slip_angle",
    "cartesian_rhs",
    "frenet_rhs",
    "lateral_acceleration",
    "rk4_step",
    "casadi_frenet_dynamics",
    "casadi_cartesian_dynamics",
    "Plant",
]




# --------------------------------------------------------------------------------------
# The model, written once over an ``ops`` namespace (math, numpy or casadi).
# --------------------------------------------------------------------------------------


def slip_angle(delta: Any, p: VehicleParams, ops: Any = math) -> Any:
    """Side-slip angle at the centre of gravity, beta = atan(lr / L * tan(delta)) [rad]."""
    return ops.atan(p.lr / p.wheelbase * ops.tan(delta))


def yaw_rate(v: Any, delta: Any, p: VehicleParams, ops: Any = math) -> Any:
    """psi_dot = v / L * cos(beta) * tan(delta) [rad/s]."""
    beta = slip_angle(delta, p, ops)
    return v / p.wheelbase * ops.cos(beta) * ops.tan(delta)


def lateral_acceleration(v: Any, delta: Any, p: VehicleParams, ops: Any = math) -> Any:
    """a_lat = v * psi_dot = v^2 / L * cos(beta) * tan(delta) [m/s^2]."""
    return v * yaw_rate(v, delta, p, ops)


def cartesian_rhs(x: Sequence[Any], u: Sequence[Any], p: VehicleParams, ops: Any = math) -> list:
    """Time derivative of the Cartesian state (x, y, psi, v, delta) under input (a, delta_dot)."""
    _, _, psi, v, delta = x
    beta = slip_angle(delta, p, ops)
    return [
        v * ops.cos(psi + beta),
        v * ops.sin(psi + beta),
        v / p.wheelbase * ops.cos(beta) * ops.tan(delta),
        u[0],
        u[1],
    ]


def frenet_rhs(x: Sequence[Any], u: Sequence[Any], kappa: Any, p: VehicleParams, ops: Any = math) -> list:
    """Time derivative of the Frenet state (s, n, e, v, delta) along a line of curvature ``kappa`` [1/m]."""
    _, n, e, v, delta = x
    beta = slip_angle(delta, p, ops)
    s_dot = v * ops.cos(e + beta) / (1.0 - kappa * n)
    return [
        s_dot,
        v * ops.sin(e + beta),
        v / p.wheelbase * ops.cos(beta) * ops.tan(delta) - kappa * s_dot,
        u[0],
        u[1],
    ]


def rk4_step(rhs: Callable[[Sequence[Any], Sequence[Any]], list], x: Sequence[Any], u: Sequence[Any],
             dt: float, substeps: int = 1) -> list:
    """Classical fourth-order Runge-Kutta over ``dt`` [s] in ``substeps`` equal steps, input held.

    Works on lists of floats and on lists of CasADi scalars alike.
    """
    h = dt / substeps
    x = list(x)
    for _ in range(substeps):
        k1 = rhs(x, u)
        k2 = rhs([xi + 0.5 * h * ki for xi, ki in zip(x, k1)], u)
        k3 = rhs([xi + 0.5 * h * ki for xi, ki in zip(x, k2)], u)
        k4 = rhs([xi + h * ki for xi, ki in zip(x, k3)], u)
        x = [xi + h / 6.0 * (a + 2.0 * b + 2.0 * c + d) for xi, a, b, c, d in zip(x, k1, k2, k3, k4)]
    return x


def casadi_frenet_dynamics(p: VehicleParams = AV21, dt: float | None = None, substeps: int = 1):
    """CasADi function of the Frenet model.

    With ``dt=None``: ``f(x[5], u[2], kappa) -> x_dot[5]`` (continuous time).
    With ``dt``: ``F(x[5], u[2], kappa) -> x_next[5]``, RK4 over ``dt`` [s] in ``substeps`` steps.
    """
    import casadi as ca

    x = ca.SX.sym("x", 5)
    u = ca.SX.sym("u", 2)
    kappa = ca.SX.sym("kappa")
    xs = [x[i] for i in range(5)]
    us = [u[0], u[1]]
    if dt is None:
        out = frenet_rhs(xs, us, kappa, p, ca)
        return ca.Function("frenet_ode", [x, u, kappa], [ca.vertcat(*out)], ["x", "u", "kappa"], ["x_dot"])
    out = rk4_step(lambda xx, uu: frenet_rhs(xx, uu, kappa, p, ca), xs, us, dt, substeps)
    return ca.Function("frenet_rk4", [x, u, kappa], [ca.vertcat(*out)], ["x", "u", "kappa"], ["x_next"])


def casadi_cartesian_dynamics(p: VehicleParams = AV21, dt: float | None = None, substeps: int = 1):
    """CasADi function of the Cartesian model, continuous (``dt=None``) or RK4-discretised."""
    import casadi as ca

    x = ca.SX.sym("x", 5)
    u = ca.SX.sym("u", 2)
    xs = [x[i] for i in range(5)]
    us = [u[0], u[1]]
    if dt is None:
        out = cartesian_rhs(xs, us, p, ca)
        return ca.Function("cartesian_ode", [x, u], [ca.vertcat(*out)], ["x", "u"], ["x_dot"])
    out = rk4_step(lambda xx, uu: cartesian_rhs(xx, uu, p, ca), xs, us, dt, substeps)
    return ca.Function("cartesian_rk4", [x, u], [ca.vertcat(*out)], ["x", "u"], ["x_next"])


# --------------------------------------------------------------------------------------
# Plant
# --------------------------------------------------------------------------------------


class Plant:
    """Numeric Cartesian plant: the bicycle with slip integrated by RK4 sub-steps.

    The plant enforces the actuator limits: ``a`` is clipped to ``[a_min, a_max]``,
    ``delta_dot`` to ``+-steer_rate_max``; after every sub-step the steering angle is
    clipped to ``+-steer_max`` and the speed to ``>= 0`` (the car does not reverse).
    A non-finite input raises ``ValueError``.
    """

    def __init__(self, params: VehicleParams = AV21, dt: float = 0.1, substeps: int = 4):
        if dt <= 0 or substeps < 1:
            raise ValueError("dt must be positive and substeps >= 1")
        self.params = params
        self.dt = float(dt)
        """Control period [s]."""
        self.substeps = int(substeps)

    def clip_input(self, u: Sequence[float]) -> tuple[float, float]:
        """Input clipped to the actuator limits."""
        a, dd = float(u[0]), float(u[1])
        if not (math.isfinite(a) and math.isfinite(dd)):
            raise ValueError(f"non-finite control input {u!r}")
        p = self.params
        return min(max(a, p.a_min), p.a_max), min(max(dd, -p.steer_rate_max), p.steer_rate_max)

    def step(self, x: Sequence[float], u: Sequence[float]) -> np.ndarray:
        """State after one control period ``dt`` with input ``u`` held (zero-order hold).

        ``substeps`` RK4 steps of :func:`cartesian_rhs`, in one compiled call (:func:`_kinematic_rk4`).
        """
        p = self.params
        a, dd = self.clip_input(u)
        px, py, psi, v, delta = map(float, x)
        return np.array(_kinematic_rk4(px, py, psi, v, delta, a, dd, self.dt / self.substeps, self.substeps,
                                       p.lr / p.wheelbase, p.wheelbase, p.steer_max))


@kernel
def _kinematic_rk4(px, py, psi, v, delta, a, dd, h, substeps, k_slip, wb, steer_max):
    """``substeps`` steps of ``rk4_step(cartesian_rhs, ...)`` of length ``h`` [s], written out (the same
    floating-point operations in the same order, so the same result to the last bit, which
    tests/test_fast_paths.py checks): v and delta have the constant rates a and delta_dot, so only the
    rates of x, y and psi are evaluated. v is kept >= 0 and delta within +-steer_max after each step
    (as Python's ``max``/``min`` pick)."""
    half, sixth = 0.5 * h, h / 6.0
    for _ in range(substeps):
        x1, y1, r1 = _rates(psi, v, delta, k_slip, wb)
        v2, delta2 = v + half * a, delta + half * dd  # the stage states of k2 and k3
        x2, y2, r2 = _rates(psi + half * r1, v2, delta2, k_slip, wb)
        x3, y3, r3 = _rates(psi + half * r2, v2, delta2, k_slip, wb)
        x4, y4, r4 = _rates(psi + h * r3, v + h * a, delta + h * dd, k_slip, wb)
        px = px + sixth * (x1 + 2.0 * x2 + 2.0 * x3 + x4)
        py = py + sixth * (y1 + 2.0 * y2 + 2.0 * y3 + y4)
        psi = psi + sixth * (r1 + 2.0 * r2 + 2.0 * r3 + r4)
        v_new = v + sixth * (a + 2.0 * a + 2.0 * a + a)
        v = 0.0 if 0.0 > v_new else v_new
        d_new = delta + sixth * (dd + 2.0 * dd + 2.0 * dd + dd)
        d_new = -steer_max if -steer_max > d_new else d_new
        delta = steer_max if steer_max < d_new else d_new
    return px, py, psi, v, delta


@kernel
def _rates(psi, v, delta, k_slip, wb):
    """(x', y', psi') of :func:`cartesian_rhs`."""
    tan_delta = math.tan(delta)
    beta = math.atan(k_slip * tan_delta)
    return v * math.cos(psi + beta), v * math.sin(psi + beta), v / wb * math.cos(beta) * tan_delta
