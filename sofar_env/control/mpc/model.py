"""The optimal control problem of the MPC-DCBF, defined once for both of its solvers.

Problem (paper, "Low-Level Control via MPC--DCBF", soft DCBF variant)
-------------------------------------------------------------------
Multiple shooting over the time grid ``t_0 = 0, t_1 = dt_0, t_k = dt_0 + (k - 1) ts``
(:meth:`MPCConfig.time_grid`) with states ``x_0..x_N`` (Frenet ``(s, n, e, v, delta)``,
``s`` relative to the ego) and inputs ``u_0..u_{N-1}`` (``(a, delta_dot)``)::

    min  sum_{k=0..N-1} ||u_k||_R^2 + ||x_{k+1} - x_ref_{k+1}||_Q^2
         + sum over every slack sigma of  z sigma + Z sigma^2 / 2          (L1 + L2)
    s.t. x_0 = current state,  x_{k+1} = f(x_k, u_k, kappa_k, dt_k)        (RK4 of frenet_rhs)
         a_min <= a_k <= a_max,  |delta_dot_k| <= 0.35,  |delta_k| <= 0.25,  v_k >= 0  (hard)
         |a_lat(x_k)| <= 15 + sigma^lat_k                                          (k = 1..N)
         n_min_k + margin - sigma^trk_k <= n_k <= n_max_k - margin + sigma^trk_k    (k = 1..N)
           (with MPCConfig.track_rows = "ends": for both n_k + l sin e_k and n_k - l sin e_k,
            l = max(l_f, l_r), the two ends of the car)
         (1 - gamma) h(x_k, o_ik) - h(x_{k+1}, o_i,k+1) <= sigma^cbf_ik  (k = 0..N-1, every slot i)
         sigma >= 0

with ``x_ref_k = (., n_ref_k, 0, v_ref_k, 0)`` and terminal weight Q. The DCBF holds on
**every** transition, including ``x_0 -> x_1`` (the authors' reference code misses it).
Opponents are predicted at constant velocity, ``o_ik = (s_i + v_i t_k, n_i, v_i, c_i)``
(:func:`predict_opponents`); with a lateral rate ``n_dot_i`` known, ``n_i + n_dot_i t_k``, and
``c_i = n_dot_i / max(v_i, 1 m/s)`` (clipped to [-1, 1]) the sine of its course angle to the track, which
only a barrier with ``BarrierParams.heading_extent`` > 0 uses (0 without a rate).

Time grid. The first interval ``dt_0`` defaults to the plant period ``control_dt``
(``MPCConfig.first_step``), the others are ``ts``. The first DCBF transition is then
exactly the step the plant takes before the next solve, so
``h(x(t + control_dt)) >= (1 - gamma) h(x(t))`` is what the controller certifies in
closed loop whenever the first-stage barrier slack is zero. Set ``first_step = ts``
for the uniform grid of the authors' reference code (then the closed-loop condition
only holds approximately when ``control_dt != ts``).

Integrator: one RK4 step per interval (``integrator_substeps = 1``). Measured
against a 64-sub-step RK4 over 20 random horizons (20-70 m/s, curvature up to
1/60 m^-1, full braking and steering rates), one step errs by at most 0.8 mm in s
and n (two sub-steps: 0.05 mm) - far below what matters, at half the cost.

One definition, two solvers
---------------------------
The nonlinear functions of a stage - the RK4 step ``f``, the lateral acceleration and
the barrier against every opponent slot - are one CasADi function
(:func:`stage_function`). The real-time iteration evaluates its Jacobians
(:func:`linearisation_function`, derived from that very function); the IPOPT
reference (:mod:`.reference`) calls it inside its NLP. The numeric data of the cost
and of the bounds (:func:`tracking_weights`, :func:`stage_reference`,
:func:`slack_weights`, :func:`variable_box`, :func:`track_limits`) and the opponent
prediction and selection are shared the same way, so the two solvers cannot drift.
"""

from __future__ import annotations

import hashlib

import numpy as np

from ..._jit import kernel, maximum, minimum
from ...vehicle import VehicleParams, frenet_rhs, lateral_acceleration, rk4_step
from ..barrier import BarrierParams, barrier_expr, barrier_table, casadi_ops
from .types import MPCConfig

__all__ = ["DUMMY_OPPONENT", "OPPONENT_ROWS", "definition_name", "stage_function", "linearisation_function", "tracking_weights",
           "stage_reference", "slack_weights", "variable_box", "track_limits", "predict_opponents",
           "select_opponents", "relevant_slots"]

DUMMY_OPPONENT = (50.0, 0.0, 0.0, 0.0)
"""(s, n, v, sin_course) put in opponent slots without an opponent: finite, far from the ego; its outputs
are unused."""
OPPONENT_ROWS = 4
"""Rows of an opponent column of the stage function: (s, n, v, sin_course)."""
_COURSE_MIN_SPEED = 1.0
"""Speed below which the course angle of an opponent is taken from its lateral rate over this speed [m/s]."""


# --------------------------------------------------------------------------------------
# CasADi: the stage function and its linearisation
# --------------------------------------------------------------------------------------


def definition_name(vehicle: VehicleParams, bp: BarrierParams, slots: int, substeps: int) -> str:
    """Name of the stage functions, unique per problem definition (and CasADi version)."""
    import casadi as ca

    parts = (vehicle, bp, slots, substeps, OPPONENT_ROWS, ca.__version__)
    return "sofar_mpc_stage_" + hashlib.sha1(repr(parts).encode()).hexdigest()[:12]


def stage_function(vehicle: VehicleParams, bp: BarrierParams, slots: int, substeps: int,
                   name: str = "sofar_mpc_stage"):
    """CasADi function ``(x[5], u[2], kappa, dt, o[4 x slots]) -> (f[5], alat, h[slots])`` of one stage.

    ``f``: the state after ``dt`` [s] (RK4 of :func:`~sofar_env.vehicle.frenet_rhs` in
    ``substeps`` steps, curvature ``kappa`` [1/m], input ``u`` held); ``alat``: the lateral
    acceleration at ``x`` [m/s^2]; ``h``: the barrier of ``x`` against each opponent
    column ``(s, n, v, sin_course)`` of ``o`` [-]. ``slots`` must be >= 1.
    """
    import casadi as ca

    x = ca.SX.sym("x", 5)
    u = ca.SX.sym("u", 2)
    kappa = ca.SX.sym("kappa")
    dt = ca.SX.sym("dt")
    o = ca.SX.sym("o", OPPONENT_ROWS, slots)
    xs = [x[i] for i in range(5)]
    f = ca.vertcat(*rk4_step(lambda xx, uu: frenet_rhs(xx, uu, kappa, vehicle, ca), xs, [u[0], u[1]], dt, substeps))
    alat = lateral_acceleration(x[3], x[4], vehicle, ca)
    ops = casadi_ops()
    h = ca.vertcat(*[barrier_expr(x[0], x[1], x[3], o[0, i], o[1, i], o[2, i], bp, ops, x[2], o[3, i])
                     for i in range(slots)])
    return ca.Function(name, [x, u, kappa, dt, o], [f, alat, h], ["x", "u", "kappa", "dt", "o"], ["f", "alat", "h"])


def linearisation_function(stage, name: str):
    """``(x, u, kappa, dt, o) -> (f, A, B, alat, dalat, h, dh)``: ``stage`` and its Jacobians.

    ``A = df/dx``, ``B = df/du`` (sparse), ``dalat = d alat / d(v, delta)`` (1 x 2) and
    ``dh`` (3 x slots, dense) column i the gradient of ``h_i`` with respect to ``(s, n, v)``. With
    ``BarrierParams.heading_extent`` h also depends on the heading error; its linearisation keeps the
    widening of the ellipse at its value at the linearisation point (no gradient in e; the opponent's
    course is a parameter); with ``heading_sides = "toward"`` the widening also varies with the gap and the
    lateral offset, and the gradient in (s, n) includes that.
    """
    import casadi as ca

    x, u, kappa, dt, o = stage.sx_in()
    f, alat, h = stage(x, u, kappa, dt, o)
    dalat = ca.jacobian(alat, ca.vertcat(x[3], x[4]))
    snv = ca.vertcat(x[0], x[1], x[3])
    dh = ca.horzcat(*[ca.jacobian(h[i], snv).T for i in range(h.numel())])
    return ca.Function(name, [x, u, kappa, dt, o],
                       [f, ca.jacobian(f, x), ca.jacobian(f, u), alat, dalat, h, ca.densify(dh)],
                       ["x", "u", "kappa", "dt", "o"], ["f", "A", "B", "alat", "dalat", "h", "dh"])


# --------------------------------------------------------------------------------------
# Numeric data of the cost and the bounds, per stage block (u_k, x_{k+1}), k = 0..N-1
# --------------------------------------------------------------------------------------


def tracking_weights(cfg: MPCConfig) -> np.ndarray:
    """(7,) weights of the quadratic cost on the block ``(u_k, x_{k+1})``: ``(r, q)``."""
    return np.concatenate([np.asarray(cfg.r, dtype=float), np.asarray(cfg.q, dtype=float)])


def stage_reference(arrays: np.ndarray) -> np.ndarray:
    """(N, 7) reference of the blocks ``(u_k, x_{k+1})``: ``(0, 0, ., n_ref, 0, v_ref, 0)``.

    ``arrays``: the (5, N+1) stage rows (kappa, n_ref, v_ref, n_min, n_max). The weight
    of ``s`` is zero, so its reference is irrelevant (0).
    """
    ref = np.zeros((arrays.shape[1] - 1, 7))
    ref[:, 3] = arrays[1, 1:]
    ref[:, 5] = arrays[2, 1:]
    return ref


def slack_weights(cfg: MPCConfig, lat: bool, trk: bool, m: int, buf: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """(L1, L2) weights of the slacks of a block, in the order lateral acceleration (if
    ``lat``), track (if ``trk``), track buffer (if ``buf``, ``MPCConfig.track_buffer``), DCBF of each of the
    ``m`` opponent slots."""
    z1 = ([cfg.lat_acc_slack[0]] * int(lat) + [cfg.track_slack[0]] * int(trk) + [cfg.track_buffer_slack[0]] * int(buf)
          + [cfg.barrier_slack[0]] * m)
    z2 = ([cfg.lat_acc_slack[1]] * int(lat) + [cfg.track_slack[1]] * int(trk) + [cfg.track_buffer_slack[1]] * int(buf)
          + [cfg.barrier_slack[1]] * m)
    return np.asarray(z1, dtype=float), np.asarray(z2, dtype=float)


def variable_box(vehicle: VehicleParams) -> tuple[np.ndarray, np.ndarray]:
    """(7,) hard lower and upper bounds on the block ``(u_k, x_{k+1})``.

    The bound ``v >= 0`` is written ``-0.0``: the RTI bounds the step ``dv`` by
    ``-0.0 - vbar``, which is ``-vbar`` to the last bit, also for ``vbar = 0``.
    """
    p = vehicle
    inf = np.inf
    lo = np.array([p.a_min, -p.steer_rate_max, -inf, -inf, -inf, -0.0, -p.steer_max])
    hi = np.array([p.a_max, p.steer_rate_max, inf, inf, inf, inf, p.steer_max])
    return lo, hi


def track_limits(cfg: MPCConfig, arrays: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(N,) bounds ``(n_min + margin, n_max - margin)`` on ``n_{k+1}`` [m] (softened by the track slack)."""
    return arrays[3, 1:] + cfg.track_margin, arrays[4, 1:] - cfg.track_margin


# --------------------------------------------------------------------------------------
# Opponents
# --------------------------------------------------------------------------------------


def predict_opponents(rows: np.ndarray, t: np.ndarray) -> np.ndarray:
    """(len(t), M, 4) constant-velocity prediction ``(s + v t, n, v, 0)`` of the (M, 3) ``rows`` at times ``t``;
    rows (M, 4) ``(s, n, v, n_dot)`` also move across the track, ``n + n_dot t``, and give the sine of
    their course angle ``clip(n_dot / max(v, 1 m/s), -1, 1)`` as the fourth value."""
    out = np.empty((len(t), len(rows), OPPONENT_ROWS))
    predict_into(rows, t, out, np.asarray(DUMMY_OPPONENT))
    return out


@kernel
def predict_into(rows, t, out, dummy):
    """:func:`predict_opponents` of the (M, 3 or 4) ``rows`` written into ``out[:, :M]`` ((K, S, 4), S >= M),
    ``dummy`` (4,) into the slots M..S-1; one compiled call (:mod:`sofar_env._jit`) of the same
    operations as the numpy form ``s + v t``, ``n + n_dot t``, ``clip(n_dot / maximum(v, 1), -1, 1)``."""
    lateral = rows.shape[1] == 4
    for i in range(rows.shape[0]):
        s, n, v = rows[i, 0], rows[i, 1], rows[i, 2]
        n_dot = rows[i, 3] if lateral else 0.0
        course = minimum(maximum(n_dot / maximum(v, _COURSE_MIN_SPEED), -1.0), 1.0) if lateral else 0.0
        for k in range(out.shape[0]):
            out[k, i, 0] = s + v * t[k]
            out[k, i, 1] = n + n_dot * t[k] if lateral else n
            out[k, i, 2] = v
            out[k, i, 3] = course
    for i in range(rows.shape[0], out.shape[1]):
        for k in range(out.shape[0]):
            for j in range(OPPONENT_ROWS):
                out[k, i, j] = dummy[j]


def select_opponents(opp: np.ndarray, xg: np.ndarray, t: np.ndarray, cfg: MPCConfig) -> np.ndarray:
    """Up to ``max_opponents`` of the (M, 3) rows ``opp``: those inside the gap window
    ``[-opponent_range_behind, opponent_range_ahead]``, and of these (if too many) the
    ones with the smallest barrier along the guess ``xg`` at times ``t``."""
    if len(opp) == 0 or cfg.max_opponents == 0:
        return opp[:0]
    cand = _in_window(opp, -cfg.opponent_range_behind, cfg.opponent_range_ahead)
    if len(cand) > cfg.max_opponents:
        hmin = barrier_table(xg, predict_opponents(cand, t), cfg.barrier)[1]
        cand = cand[np.argsort(hmin, kind="stable")[: cfg.max_opponents]]
    return cand


def relevant_slots(h: np.ndarray, gamma: float, cfg: MPCConfig) -> np.ndarray:
    """Indices of the selected opponents that get DCBF constraints, from their barrier values
    ``h`` (N+1, M) along the warm start.

    An opponent is left out only when its barrier stays above ``opponent_h_keep`` and
    every DCBF condition ``(1 - gamma) h_k - h_{k+1} <= 0`` holds by more than
    ``opponent_dcbf_keep``: one RTI step moves the first predicted state by centimetres,
    so the first transition still satisfies the DCBF for it, and it is reconsidered at
    the next solve.
    """
    return _relevant(h, float(gamma), float(cfg.opponent_h_keep), -float(cfg.opponent_dcbf_keep))


@kernel
def _in_window(opp, lo, hi):
    """The rows of ``opp`` whose first column is in ``[lo, hi]``, in order (a copy): ``opp[(s >= lo) & (s <= hi)]``
    in one compiled call (:mod:`sofar_env._jit`)."""
    count = 0
    for i in range(opp.shape[0]):
        if opp[i, 0] >= lo and opp[i, 0] <= hi:
            count += 1
    out = np.empty((count, opp.shape[1]))
    r = 0
    for i in range(opp.shape[0]):
        if opp[i, 0] >= lo and opp[i, 0] <= hi:
            out[r] = opp[i]
            r += 1
    return out


@kernel
def _relevant(h, gamma, h_keep, dcbf_low):
    """:func:`relevant_slots` in one compiled call (:mod:`sofar_env._jit`): per column of ``h`` (K >= 2 rows),
    ``min(h) < h_keep`` or ``max((1 - gamma) h_k - h_{k+1}) > dcbf_low``, the residuals formed as in the numpy
    form; a nan in a column fails both tests, as numpy's nan-propagating ``min``/``max`` do."""
    K, M = h.shape
    keep = np.empty(M, dtype=np.intp)
    n = 0
    for i in range(M):
        low = h[0, i]
        high = (1.0 - gamma) * h[0, i] - h[1, i]
        for k in range(1, K):
            low = minimum(low, h[k, i])
            if k < K - 1:
                high = maximum(high, (1.0 - gamma) * h[k, i] - h[k + 1, i])
        if low < h_keep or high > dcbf_low:
            keep[n] = i
            n += 1
    return keep[:n].copy()
