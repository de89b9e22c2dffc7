"""The reference implementation's optimal control problem, one stage, and its linearisation.

Written from the description of the reference formulation (kinematic bicycle in the Frenet frame,
integrated by acados' ``ERK`` with 3 stages and 4 steps per interval; the soft rows ``[a_lat, track
upper, track lower, DCBF of each slot]``; the DCBF ``(1 - gamma) h(x_k) - h(x_{k+1}) <= 0`` with
``x_{k+1}`` one classical RK4 step of the interval and the reference's barrier
``h = (ds/a)^2 + (dn/b)^2 - (1 + margin)``, ``a = a0 + max(0, v - v_o)^2 / (2 a_brake)``).

:func:`linearisation` returns one CasADi function over the whole horizon (the stage function mapped
over N intervals), compiled to C once and cached (:mod:`sofar_env.control.codegen`).
"""

from __future__ import annotations

import hashlib

from ...vehicle import VehicleParams, frenet_rhs, lateral_acceleration, rk4_step
from ..codegen import CodegenInfo, compile_function
from .config import ReferenceNumerics

__all__ = ["ROWS_FIXED", "stage_function", "linearisation"]

ROWS_FIXED = 3
"""Soft rows before the DCBF rows: a_lat, track upper, track lower."""


def _kutta3(rhs, x, u, dt: float, steps: int) -> list:
    """Kutta's third-order scheme (c = 0, 1/2, 1; a21 = 1/2, a31 = -1, a32 = 2; b = 1/6, 2/3, 1/6)."""
    h = dt / steps
    for _ in range(steps):
        k1 = rhs(x, u)
        k2 = rhs([xi + 0.5 * h * a for xi, a in zip(x, k1)], u)
        k3 = rhs([xi + h * (-a + 2.0 * b) for xi, a, b in zip(x, k1, k2)], u)
        x = [xi + h * (a / 6.0 + 2.0 * b / 3.0 + c / 6.0) for xi, a, b, c in zip(x, k1, k2, k3)]
    return x


def stage_function(rn: ReferenceNumerics, vehicle: VehicleParams, ts: float):
    """CasADi ``(x[5], u[2], p[3 + 3 slots + 1]) -> (f[5], c[3 + slots])``: the state after one interval
    of ``ts`` [s] and the soft rows at ``(x, u)``. ``p = (kappa, n_max, n_min, (s_o, n_o, v_o) per slot,
    gamma)``; each row must be ``<= 0`` except a_lat, which must lie in ``[-lat_acc_max, lat_acc_max]``."""
    import casadi as ca

    x = ca.SX.sym("x", 5)
    u = ca.SX.sym("u", 2)
    p = ca.SX.sym("p", 4 + 3 * rn.slots)
    kappa, n_max, n_min, gamma = p[0], p[1], p[2], p[3 + 3 * rn.slots]
    xs, us = [x[i] for i in range(5)], [u[0], u[1]]

    def rhs(xx, uu):
        return frenet_rhs(xx, uu, kappa, vehicle, ca)

    f = ca.vertcat(*_kutta3(rhs, xs, us, ts, rn.rk_steps))
    x1 = rk4_step(rhs, xs, us, ts, 1)

    def h(state, s_o, n_o, v_o):
        a = rn.a0 + ca.fmax(0.0, state[3] - v_o) ** 2 / (2.0 * rn.a_brake)
        return ((state[0] - s_o) / a) ** 2 + ((state[1] - n_o) / rn.b) ** 2 - (1.0 + rn.margin)

    rows = [lateral_acceleration(x[3], x[4], vehicle, ca), x[1] - n_max + rn.track_margin,
            n_min + rn.track_margin - x[1]]
    for i in range(rn.slots):
        s_o, n_o, v_o = p[3 + 3 * i], p[4 + 3 * i], p[5 + 3 * i]
        rows.append((1.0 - gamma) * h(xs, s_o, n_o, v_o) - h(x1, s_o + v_o * ts, n_o, v_o))
    return ca.Function("refnum_stage", [x, u, p], [f, ca.vertcat(*rows)], ["x", "u", "p"], ["f", "c"])


def linearisation(rn: ReferenceNumerics, vehicle: VehicleParams, ts: float, horizon: int,
                  cache_dir: str | None = None, compile: bool = True):
    """``(function, CodegenInfo)``: ``F(X[5 x N], U[2 x N], P[np x N]) -> (f, A, B, c, Cx, Cu)``, the stage
    function and its Jacobians at every interval, as horizontally stacked blocks (``A``: 5 x 5N, ...)."""
    import casadi as ca

    stage = stage_function(rn, vehicle, ts)
    x, u, p = stage.sx_in()
    f, c = stage(x, u, p)
    lin = ca.Function("refnum_lin", [x, u, p],
                      [f, ca.densify(ca.jacobian(f, x)), ca.densify(ca.jacobian(f, u)), c,
                       ca.densify(ca.jacobian(c, x)), ca.densify(ca.jacobian(c, u))])
    key = hashlib.sha1(repr((rn, vehicle, ts, horizon, ca.__version__)).encode()).hexdigest()[:12]
    mapped = lin.map(horizon)
    X, U, P = ca.MX.sym("X", 5, horizon), ca.MX.sym("U", 2, horizon), ca.MX.sym("P", p.numel(), horizon)
    func = ca.Function(f"sofar_refnum_{key}", [X, U, P], mapped(X, U, P),
                       ["X", "U", "P"], ["f", "A", "B", "c", "Cx", "Cu"])
    out: tuple = compile_function(func, cache_dir, enabled=compile)
    return out[0], out[1]


def _info(out) -> CodegenInfo:  # pragma: no cover - typing helper
    return out[1]
