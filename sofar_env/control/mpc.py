"""MPC with discrete-time control barrier functions (MPC-DCBF) as an SQP real-time iteration.

Problem (paper, "Low-Level Control via MPC--DCBF", soft DCBF variant)
-------------------------------------------------------------------
Multiple shooting over the time grid ``t_0 = 0, t_1 = dt_0, t_k = dt_0 + (k - 1) ts``
with states ``x_0..x_N`` (Frenet ``(s, n, e, v, delta)``, ``s`` relative to the ego)
and inputs ``u_0..u_{N-1}`` (``(a, delta_dot)``)::

    min  sum_{k=1..N} ||x_k - x_ref_k||_Q^2 + sum_{k=0..N-1} ||u_k||_R^2
         + sum over every slack sigma of  z sigma + Z sigma^2 / 2          (L1 + L2)
    s.t. x_0 = current state,  x_{k+1} = RK4(frenet_rhs, x_k, u_k, kappa_k, dt_k)
         a_min <= a_k <= a_max,  |delta_dot_k| <= 0.35,  |delta_k| <= 0.25,  v_k >= 0  (hard)
         |a_lat(x_k)| <= 15 + sigma^lat_k                                          (k = 1..N)
         n_min_k + margin - sigma^trk_k <= n_k <= n_max_k - margin + sigma^trk_k    (k = 1..N)
         (1 - gamma) h(x_k, o_ik) - h(x_{k+1}, o_i,k+1) <= sigma^cbf_ik  (k = 0..N-1, every slot i)
         sigma >= 0

with ``x_ref_k = (., n_ref_k, 0, v_ref_k, 0)`` and terminal weight Q. The DCBF holds on
**every** transition, including ``x_0 -> x_1`` (the reference implementation misses it).
Opponents are predicted at constant velocity, ``o_ik = (s_i + v_i t_k, n_i, v_i)``.

Time grid. The first interval ``dt_0`` defaults to the plant period ``control_dt``
(``MPCConfig.first_step``), the others are ``ts``. The first DCBF transition is then
exactly the step the plant takes before the next solve, so
``h(x(t + control_dt)) >= (1 - gamma) h(x(t))`` is what the controller certifies in
closed loop whenever the first-stage barrier slack is zero. Set ``first_step = ts``
for the uniform grid of the reference (then the closed-loop condition only holds
approximately when ``control_dt != ts``).

Integrator: one RK4 step per interval (``integrator_substeps = 1``). Measured
against a 64-sub-step RK4 over 20 random horizons (20-70 m/s, curvature up to
1/60 m^-1, full braking and steering rates), one step errs by at most 0.8 mm in s
and n (two sub-steps: 0.05 mm) - far below what matters, at half the cost.

Real-time iteration
-------------------
One QP per :meth:`MPCDCBF.solve` (Gauss-Newton SQP, full step), linearised at the
previous solution shifted in time by ``control_dt`` (linear interpolation of the
states, zero-order hold of the inputs, linear extrapolation past the horizon) and
re-anchored so the ego is at ``s = 0``. When a barrier constraint is near-active in
the QP solution (``extra_iteration_when_active``) a second iteration re-linearises at
the new iterate: one RTI step keeps less distance than the converged solution when
an opponent is close (DESIGN.md sec. 6). A cold start (first solve, after
:meth:`MPCDCBF.reset` or a brake fallback) runs ``cold_start_iterations`` iterations.

Linearisation: one CasADi stage function (RK4 step and its Jacobians, lateral
acceleration and gradient, barrier values and gradients for every opponent slot),
mapped over the ``N + 1`` stages, is compiled to C once (:mod:`sofar_env.control.codegen`,
cached on disk) and evaluated with one ``Function.buffer()`` call per iteration
into pre-allocated numpy arrays (no per-call conversion); the sparse QP matrices are
then filled by one gather each into the data arrays of CSC matrices with a fixed
pattern. Slack variables enter the QP scaled by ``sqrt(Z)`` (Hessian entry 1 instead
of 9e4 next to R = 0.01), which made the first control 100x more accurate at equal
solver tolerance.

QP size (PIQP backend). Constraints far from the linearisation point are left out of
the QP and checked afterwards: the lateral-acceleration rows when ``|a_lat|`` stays 3 m/s^2
below its bound at every stage, the track rows when ``n`` stays 0.5 m inside the
margined edges, and each box bound (on ``a``, ``delta_dot``, ``v >= 0``, ``delta``)
farther than a fixed distance from the linearisation point. When the solution
violates a left-out constraint (by more than 1e-6), the QP is solved again with it.
A constraint that holds at the optimum of the smaller QP leaves that optimum
unchanged (it is also the optimum of the QP with the constraint, whose slack is
then zero), so the answer is that of the full QP. The gain is mostly in
interior-point iterations: far-away bounds (above all ``v >= 0`` at racing speed) cost
PIQP about 4 of its 10 iterations. The QP has a fixed pattern per number of
opponents with rows (0..``max_opponents``; unused slots have no rows at all) and
per presence of the lateral-acceleration and track rows; each pattern gets its own
PIQP instance, set up once and refreshed with ``update()`` (a left-out bound is an
infinite entry of the bound vectors, not a change of pattern).

Opponents: of the given rows, those inside the gap window
``[-opponent_range_behind, opponent_range_ahead]`` are candidates; if there are more
than ``max_opponents``, those with the smallest barrier along the warm start win.
A candidate gets no QP rows when its barrier stays above ``opponent_h_keep`` along
the warm start and all its DCBF rows are inactive there by more than
``opponent_dcbf_keep`` (it cannot constrain the first step, and it is re-examined at
the next solve); this keeps the QP small when opponents are far.

QP backends:

* ``"piqp"`` (default): proximal interior point, eps_abs 1e-7; on the 600-step closed
  loop of ``eval/bench_mpc.py`` its first control differs from a 1e-11-tolerance solve
  from the same warm start by 1e-5 m/s^2 (p95), at most 1.2e-3 m/s^2; with
  ``qp_eps_rel = 1e-9`` by 4e-7 (p95), at most 3.4e-5 m/s^2, for about 0.5 more
  interior-point iterations per solve (5-6 median);
* ``"osqp"``: ADMM (eps 1e-4, warm-started, at most 4000 iterations). With the slack
  scaling its first control errs by 4e-4 m/s^2 (p95) but up to 0.07 m/s^2, its solve
  time is heavy-tailed (p95 about 10x the median), and with an active barrier from a
  cold start it can hit the iteration limit (-> fallback). For comparison only.

:meth:`MPCDCBF.solve_converged` solves the very same NLP to convergence with IPOPT,
for validation.

Failure handling: a solver status other than solved, or a non-finite number
anywhere, never raises. The controller returns the first control of the shifted
previous plan (``status = "fallback_shift"``) while that plan still covers the
horizon, else a safe brake ``a = a_min / 2`` with the steering rate driving delta
towards 0 (``"fallback_brake"``). Failures are counted in ``n_failures`` and logged
at debug level. ``ValueError`` is raised only for malformed arguments.
"""

from __future__ import annotations

import hashlib
import logging
import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.sparse as sp

from ..vehicle import AV21, VehicleParams, frenet_rhs, lateral_acceleration, rk4_step
from .barrier import BarrierParams, _casadi_ops, barrier, barrier_expr
from .codegen import CodegenInfo, compile_function

__all__ = ["MPCConfig", "MPCStageData", "MPCResult", "MPCDCBF"]

logger = logging.getLogger(__name__)

STATUS_SOLVED = "solved"
STATUS_FALLBACK_SHIFT = "fallback_shift"
STATUS_FALLBACK_BRAKE = "fallback_brake"

_N_FIXED = 7  # per-stage variables besides the slacks: u (2) + x (5)
_DUMMY_OPPONENT = (50.0, 0.0, 0.0)  # (s, n, v) in unused opponent slots of the linearisation
# The lateral-acceleration (track) rows are left out of a QP whose linearisation point keeps
# |a_lat| below lat_acc_max by this margin [m/s^2] (n inside the margined edges by this margin [m])
# at every stage; the solution is then checked against them (tolerance below) and the QP re-solved
# with the rows when one is violated (MPCDCBF._rows_needed).
_LAT_ROWS_MARGIN = 3.0
_TRK_ROWS_MARGIN = 0.5
# Likewise each bound of the box (a, delta_dot, -, -, -, v >= 0, delta) on (u_k, x_{k+1}) whose
# linearisation point is farther from it than this distance.
_BOX_DROP_DISTANCE = np.array([2.0, 0.15, np.inf, np.inf, np.inf, 5.0, 0.08])
_ROWS_CHECK_TOL = 1e-6


@dataclass(frozen=True)
class MPCConfig:
    """Configuration of the MPC-DCBF."""

    horizon: int = 20
    """N, number of shooting intervals [-]."""
    ts: float = 0.075
    """Length of the shooting intervals after the first one [s]."""
    control_dt: float = 0.1
    """Plant period, i.e. the time between two solves; the warm start is shifted by it [s].
    0 disables the shift (repeated solves at one state then iterate SQP to convergence)."""
    first_step: float | None = None
    """Length of the first shooting interval [s]; None: ``control_dt`` (or ``ts`` when
    ``control_dt`` is 0), so the first DCBF transition spans exactly one plant period."""
    q: tuple = (0.0, 150.0, 0.0, 2.5, 0.0)
    """Diagonal state weights on (s, n, e, v, delta) [1/m^2, 1/m^2, 1/rad^2, s^2/m^2, 1/rad^2]."""
    r: tuple = (0.01, 8.0)
    """Diagonal input weights on (a, delta_dot) [s^4/m^2, s^2/rad^2]."""
    lat_acc_slack: tuple = (4e3, 4e3)
    """(L1, L2) weights of the lateral-acceleration slack [s^2/m, s^4/m^2]; cost z*sigma + Z*sigma^2/2."""
    track_slack: tuple = (3.5e4, 6e4)
    """(L1, L2) weights of the track-boundary slack [1/m, 1/m^2]."""
    barrier_slack: tuple = (9e4, 9e4)
    """(L1, L2) weights of the DCBF slack [-] (h is dimensionless)."""
    track_margin: float = 1.2
    """Distance kept between the car's reference point and each track edge [m]
    (half width 0.95 m + 0.25 m buffer)."""
    max_opponents: int = 4
    """Number of opponent slots in the QP [-]."""
    opponent_range_ahead: float = 150.0
    """Opponents with an arc-length gap above this are ignored [m]."""
    opponent_range_behind: float = 40.0
    """Opponents more than this behind the ego are ignored [m]."""
    opponent_h_keep: float = 8.0
    """Opponents whose barrier h stays above this along the warm start (and whose DCBF rows
    are all inactive by more than ``opponent_dcbf_keep``) get no rows in this QP [-].
    h = 8 is three times the ellipse's size. Use inf to keep every candidate."""
    opponent_dcbf_keep: float = 0.5
    """DCBF inactivity margin of the rule above [-]."""
    barrier: BarrierParams = field(default_factory=BarrierParams)
    """Barrier function parameters."""
    qp_solver: str = "piqp"
    """QP backend: "piqp" (accurate, default) or "osqp" (less accurate, comparison only)."""
    compile: bool = True
    """Compile the CasADi stage function to C (cached on disk); falls back to CasADi evaluation."""
    cache_dir: str | None = None
    """Cache of compiled libraries; None: $SOFAR_CACHE_DIR, $XDG_CACHE_HOME/sofar or ~/.cache/sofar."""
    extra_iteration_when_active: bool = True
    """Run a second SQP iteration when a barrier constraint is near-active (DESIGN.md sec. 6)."""
    barrier_active_tol: float = 0.05
    """A DCBF row counts as near-active when its linearised residual exceeds -this value [-]."""
    cold_start_iterations: int = 3
    """SQP iterations when there is no previous plan to warm-start from [-]."""
    integrator_substeps: int = 1
    """RK4 sub-steps per shooting interval [-]."""
    qp_eps_abs: float = 1e-7
    """Absolute tolerance of the QP solver [-]."""
    qp_eps_rel: float = 1e-9
    """Relative tolerance of the QP solver [-]."""
    qp_max_iter: int = 100
    """Iteration limit of the QP solver [-]."""

    def __post_init__(self) -> None:
        if int(self.horizon) != self.horizon or self.horizon < 2:
            raise ValueError("horizon must be an integer >= 2")
        if not (self.ts > 0.0 and math.isfinite(self.ts)):
            raise ValueError("ts must be positive")
        if not (self.control_dt >= 0.0 and math.isfinite(self.control_dt)):
            raise ValueError("control_dt must be >= 0")
        if self.first_step is not None and not (self.first_step > 0.0 and math.isfinite(self.first_step)):
            raise ValueError("first_step must be positive or None")
        if len(self.q) != 5 or len(self.r) != 2 or min(self.q) < 0.0 or min(self.r) <= 0.0:
            raise ValueError("q needs 5 non-negative weights and r 2 positive weights")
        for name in ("lat_acc_slack", "track_slack", "barrier_slack"):
            w = getattr(self, name)
            if len(w) != 2 or w[0] < 0.0 or w[1] <= 0.0:
                raise ValueError(f"{name} must be (L1 >= 0, L2 > 0)")
        if self.track_margin < 0.0:
            raise ValueError("track_margin must be >= 0")
        if int(self.max_opponents) != self.max_opponents or self.max_opponents < 0:
            raise ValueError("max_opponents must be a non-negative integer")
        if self.qp_solver not in ("piqp", "osqp"):
            raise ValueError(f"qp_solver must be 'piqp' or 'osqp', got {self.qp_solver!r}")
        if self.cold_start_iterations < 1 or self.integrator_substeps < 1 or self.qp_max_iter < 1:
            raise ValueError("iteration counts must be >= 1")

    @property
    def dt0(self) -> float:
        """Length of the first shooting interval [s]."""
        if self.first_step is not None:
            return float(self.first_step)
        return float(self.control_dt) if self.control_dt > 0.0 else float(self.ts)

    def time_grid(self) -> np.ndarray:
        """(N+1,) prediction times t_k [s]."""
        t = np.empty(self.horizon + 1)
        t[0] = 0.0
        t[1:] = self.dt0 + self.ts * np.arange(self.horizon)
        return t


@dataclass
class MPCStageData:
    """Per-stage data, arrays of length N+1, evaluated at the predicted arc lengths
    :meth:`MPCDCBF.predicted_s` (plus the ego's absolute s)."""

    kappa: np.ndarray
    """Curvature of the reference line [1/m] (entry k is used on the interval k -> k+1)."""
    n_ref: np.ndarray
    """Lateral reference, e.g. the MIQP profile d* [m]."""
    v_ref: np.ndarray
    """Speed reference [m/s]."""
    n_min: np.ndarray
    """Right track edge, -width_right [m] (raw; the MPC applies track_margin)."""
    n_max: np.ndarray
    """Left track edge, +width_left [m] (raw; the MPC applies track_margin)."""


@dataclass(frozen=True)
class MPCResult:
    """Outcome of one MPC solve."""

    u: np.ndarray
    """(2,) control to apply now, (a [m/s^2], delta_dot [rad/s]), within the hard bounds."""
    x_pred: np.ndarray
    """(N+1, 5) predicted Frenet states, s relative to the ego [m]."""
    u_pred: np.ndarray
    """(N, 2) predicted inputs."""
    status: str
    """"solved" | "fallback_shift" | "fallback_brake"."""
    success: bool
    """True when the QP (or NLP) was solved."""
    slack: dict
    """Largest slack per kind: {"lat_acc" [m/s^2], "track" [m], "barrier" [-]}."""
    barrier_min: float
    """Min over all given opponents of h at the current state [-] (inf if none)."""
    solve_time: float
    """Wall-clock time of the call [s]."""
    qp_iterations: int
    """Interior-point (or ADMM) iterations, summed over the SQP iterations."""
    sqp_iterations: int = 0
    """Number of QPs solved in this call."""
    barrier_slack_first: float = 0.0
    """Largest DCBF slack of the first transition x_0 -> x_1 [-]: when it is ~0 the
    executed step satisfies the DCBF condition (up to model error)."""
    n_opponents: int = 0
    """Number of opponents with DCBF rows in the QP."""
    qp_time: float = 0.0
    """Wall-clock time spent inside the QP solver (PIQP/OSQP set-up, update and solve) [s]."""


# --------------------------------------------------------------------------------------
# CasADi definitions
# --------------------------------------------------------------------------------------


def _stage_function(vehicle: VehicleParams, bp: BarrierParams, m_max: int, substeps: int, name: str):
    """(x, u, kappa, dt, O[3 x m_max]) -> (f, A, B, alat, dalat, h, dh) for one stage."""
    import casadi as ca

    x = ca.SX.sym("x", 5)
    u = ca.SX.sym("u", 2)
    kappa = ca.SX.sym("kappa")
    dt = ca.SX.sym("dt")
    o = ca.SX.sym("o", 3, max(m_max, 1))
    xs = [x[i] for i in range(5)]
    f = ca.vertcat(*rk4_step(lambda xx, uu: frenet_rhs(xx, uu, kappa, vehicle, ca), xs, [u[0], u[1]], dt, substeps))
    jac_a = ca.jacobian(f, x)
    jac_b = ca.jacobian(f, u)
    alat = lateral_acceleration(x[3], x[4], vehicle, ca)
    dalat = ca.jacobian(alat, ca.vertcat(x[3], x[4]))
    ops = _casadi_ops()
    hs = [barrier_expr(x[0], x[1], x[3], o[0, i], o[1, i], o[2, i], bp, ops) for i in range(max(m_max, 1))]
    h = ca.vertcat(*hs)
    dh = ca.horzcat(*[ca.jacobian(hi, ca.vertcat(x[0], x[1], x[3])).T for hi in hs])
    return ca.Function(name, [x, u, kappa, dt, o], [f, jac_a, jac_b, alat, dalat, h, ca.densify(dh)],
                       ["x", "u", "kappa", "dt", "o"], ["f", "A", "B", "alat", "dalat", "h", "dh"])


_PIQP = None


def _import_piqp():
    """The piqp module, imported on first use (an import statement costs ~1 us per solve)."""
    global _PIQP
    if _PIQP is None:
        import piqp

        _PIQP = piqp
    return _PIQP


def _definition_hash(*parts: Any) -> str:
    return hashlib.sha1(repr(parts).encode()).hexdigest()[:12]


# --------------------------------------------------------------------------------------
# QP structure for a given number of active opponents
# --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class _Layout:
    """Offsets in the flat buffer holding constants and the linearisation outputs A, B, dalat, dh."""

    slots: int
    nnz_a: int
    nnz_b: int
    stages: int
    lat_scale: float
    trk_scale: float
    cbf_scale: float

    one: int = 0
    lat_neg: int = 1
    lat_pos: int = 2
    trk_neg: int = 3
    trk_pos: int = 4
    cbf_neg: int = 5
    n_const: int = 6

    @property
    def off_a(self) -> int:
        return self.n_const

    @property
    def off_b(self) -> int:
        return self.off_a + self.stages * self.nnz_a

    @property
    def off_dal(self) -> int:
        return self.off_b + self.stages * self.nnz_b

    @property
    def off_dh(self) -> int:
        return self.off_dal + self.stages * 2

    @property
    def size(self) -> int:
        return self.off_dh + self.stages * self.slots * 3

    def constants(self) -> np.ndarray:
        return np.array([1.0, -self.lat_scale, self.lat_scale, -self.trk_scale, self.trk_scale, -self.cbf_scale])


class _QPStructure:
    """Fixed sparsity of the RTI QP with ``m`` active opponent slots, and its backend.

    Variables, stage-major: block k (k = 0..N-1) = [du_k (2), dx_{k+1} (5),
    sigma_lat_{k+1} (if ``lat``), sigma_trk_{k+1} (if ``trk``), sigma_cbf_{k,0..m-1}].
    Rows of G, stage-major: [lat up, lat low] (if ``lat``), [trk up, trk low] (if ``trk``),
    cbf_0..m-1. A structure without the lateral-acceleration (or track) rows is used only
    when its solution is verified to satisfy them (see :meth:`MPCDCBF._rows_needed`).
    """

    def __init__(self, cfg: MPCConfig, vehicle: VehicleParams, m: int, lat: bool, trk: bool, a_sp: tuple,
                 b_sp: tuple, layout: "_Layout"):
        n_h = cfg.horizon
        self.m = m
        self.lat = lat
        self.trk = trk
        col = _N_FIXED
        self.col_lat = col
        col += int(lat)
        self.col_trk = col
        col += int(trk)
        self.col_cbf = col
        self.nb = nb = col + m
        self.nz = n_h * nb
        row = 0
        self.row_lat = row
        row += 2 * int(lat)
        self.row_trk = row
        row += 2 * int(trk)
        self.row_cbf = row
        self.nr = nr = row + m
        iu = np.arange(n_h) * nb  # column of du_k
        ix = iu + 2  # column of dx_{k+1}

        # ---- equality: dx_{k+1} - A_k dx_k - B_k du_k = f_k - xbar_{k+1}
        a_rows, a_cols = a_sp
        b_rows, b_cols = b_sp
        rows, cols = [], []
        rows.append(np.repeat(5 * np.arange(n_h), 5) + np.tile(np.arange(5), n_h))
        cols.append(np.repeat(ix, 5) + np.tile(np.arange(5), n_h))
        kk = np.arange(1, n_h)
        rows.append((5 * kk)[:, None] + a_rows[None, :])
        cols.append(ix[kk - 1][:, None] + a_cols[None, :])
        kk = np.arange(n_h)
        rows.append((5 * kk)[:, None] + b_rows[None, :])
        cols.append(iu[:, None] + b_cols[None, :])
        self.eq_rows = np.concatenate([r.ravel() for r in rows])
        self.eq_cols = np.concatenate([c.ravel() for c in cols])
        self.n_eq = 5 * n_h

        # ---- inequalities and where each entry comes from: an index into the flat linearisation
        # buffer (see _Layout), a constant factor, and for DCBF entries the slot and a (1 - gamma) flag.
        # Slack scaling: the QP variable is sigma~ = sigma * sqrt(Z), so that its Hessian entry is 1
        # instead of 9e4 next to R = 0.01 (measured: 100x smaller first-control error at equal tolerance).
        lay = layout
        kk1 = np.arange(1, n_h)
        kk = np.arange(n_h)
        base = np.arange(n_h) * nr
        rows, cols, src = [], [], []
        if lat:  # lateral acceleration (v, delta of x_{k+1}) and its slack
            dal = (lay.off_dal + (kk + 1)[:, None] * 2 + np.arange(2)[None, :]).ravel()
            for r_off, sgn in ((0, lay.lat_neg), (1, lay.lat_pos)):
                rows.append(np.repeat(base + self.row_lat + r_off, 2))
                cols.append((ix[:, None] + np.array([3, 4])[None, :]).ravel())
                src.append(dal)
                rows.append(base + self.row_lat + r_off)
                cols.append(iu + self.col_lat)
                src.append(np.full(n_h, sgn))
        if trk:  # track: n of x_{k+1} and its slack
            for r_off, sgn in ((0, lay.trk_neg), (1, lay.trk_pos)):
                rows.append(base + self.row_trk + r_off)
                cols.append(ix + 1)
                src.append(np.full(n_h, lay.one))
                rows.append(base + self.row_trk + r_off)
                cols.append(iu + self.col_trk)
                src.append(np.full(n_h, sgn))
        n_fixed = sum(len(r) for r in rows)
        slot = [np.full(n_fixed, m)]
        gam = [np.zeros(n_fixed)]
        fac = [np.ones(n_fixed)]
        if m > 0:
            sn_v = np.array([0, 1, 3])
            # x_k part for k >= 1 (x_0 is fixed)
            r = (base[kk1][:, None, None] + self.row_cbf + np.arange(m)[None, :, None]) + 0 * sn_v[None, None, :]
            c = ix[kk1 - 1][:, None, None] + 0 * np.arange(m)[None, :, None] + sn_v[None, None, :]
            rows.append(r.ravel())
            cols.append(c.ravel())
            # x_{k+1} part
            r = (base[kk][:, None, None] + self.row_cbf + np.arange(m)[None, :, None]) + 0 * sn_v[None, None, :]
            c = ix[kk][:, None, None] + 0 * np.arange(m)[None, :, None] + sn_v[None, None, :]
            rows.append(r.ravel())
            cols.append(c.ravel())
            rows.append((base[:, None] + self.row_cbf + np.arange(m)[None, :]).ravel())
            cols.append((iu[:, None] + self.col_cbf + np.arange(m)[None, :]).ravel())
            comp = np.arange(3)[None, None, :]
            slots = np.arange(m)[None, :, None]
            base0 = lay.off_dh + kk1[:, None, None] * (lay.slots * 3) + comp + 0 * slots
            base1 = lay.off_dh + (kk + 1)[:, None, None] * (lay.slots * 3) + comp + 0 * slots
            src += [base0.ravel(), base1.ravel(), np.full(n_h * m, lay.cbf_neg)]
            slot += [(slots + 0 * kk1[:, None, None] + 0 * comp).ravel(),
                     (slots + 0 * kk[:, None, None] + 0 * comp).ravel(), np.full(n_h * m, m)]
            gam += [np.ones(base0.size), np.zeros(base1.size + n_h * m)]
            fac += [np.zeros(base0.size), -np.ones(base1.size), np.ones(n_h * m)]
        empty = np.zeros(0, dtype=np.int64)
        self.g_rows = np.concatenate(rows) if rows else empty
        self.g_cols = np.concatenate(cols) if cols else empty
        self.n_in = n_h * nr
        g_src = np.concatenate(src).astype(np.int64) if src else empty
        g_slot = np.concatenate(slot)
        g_gam = np.concatenate(gam)
        g_fac = np.concatenate(fac)

        z2 = [cfg.lat_acc_slack[1]] * int(lat) + [cfg.track_slack[1]] * int(trk) + [cfg.barrier_slack[1]] * m
        z1 = [cfg.lat_acc_slack[0]] * int(lat) + [cfg.track_slack[0]] * int(trk) + [cfg.barrier_slack[0]] * m
        self.slack_scale = 1.0 / np.sqrt(np.asarray(z2, dtype=float))
        na, nbb = len(a_rows), len(b_rows)
        eq_src = np.concatenate([np.full(5 * n_h, lay.one),
                                 (lay.off_a + kk1[:, None] * na + np.arange(na)[None, :]).ravel(),
                                 (lay.off_b + kk[:, None] * nbb + np.arange(nbb)[None, :]).ravel()])
        eq_fac = np.concatenate([np.ones(5 * n_h), -np.ones((n_h - 1) * na + n_h * nbb)])

        # ---- cost: P constant diagonal; c buffer with the constant slack weights
        self.q2 = 2.0 * np.asarray(cfg.q, float)
        self.r2 = 2.0 * np.asarray(cfg.r, float)
        pdiag = np.concatenate([self.r2, self.q2, np.ones(nb - _N_FIXED)])
        self.P = sp.diags(np.tile(pdiag, n_h)).tocsc()
        self.c_buf = np.zeros((n_h, nb))
        self.c_buf[:, _N_FIXED:] = self.slack_scale * np.asarray(z1, dtype=float)
        self.c_flat = self.c_buf.reshape(-1)
        # the weights of c[:, :7] = w7 * (x7 - ref7) (MPCDCBF._assemble), one row per stage: a
        # same-shape product runs as one numpy loop, a broadcast (7,) row as one loop per stage
        self.w7 = np.tile(np.concatenate([self.r2, self.q2]), (n_h, 1))
        # ---- bound buffers; entries that are never written keep their infinite / zero values
        self.hl_buf = np.full((n_h, nr), -np.inf)
        self.hu_buf = np.full((n_h, nr), np.inf)
        self.xl_buf = np.full((n_h, nb), -np.inf)
        self.xu_buf = np.full((n_h, nb), np.inf)
        self.xl_buf[:, _N_FIXED:] = 0.0
        self.b_buf = np.zeros((n_h, 5))
        self.data = (self.c_flat, self.b_buf.reshape(-1), self.hl_buf.reshape(-1), self.hu_buf.reshape(-1),
                     self.xl_buf.reshape(-1), self.xu_buf.reshape(-1))
        # views of the buffers written by MPCDCBF._assemble (made once, not per call)
        self.c7 = self.c_buf[:, :_N_FIXED]
        self.xl7 = self.xl_buf[:, :_N_FIXED]
        self.xu7 = self.xu_buf[:, :_N_FIXED]
        if lat:
            self.hu_lat, self.hl_lat = self.hu_buf[:, self.row_lat], self.hl_buf[:, self.row_lat + 1]
        if trk:
            self.hu_trk, self.hl_trk = self.hu_buf[:, self.row_trk], self.hl_buf[:, self.row_trk + 1]
        self.hu_cbf = self.hu_buf[:, self.row_cbf:]

        # ---- CSC patterns; entry sources permuted to CSC data order
        self.A, perm = self._csc(self.eq_rows, self.eq_cols, self.n_eq)
        self.a_src, self.a_fac = eq_src[perm], eq_fac[perm]
        self.G, perm = self._csc(self.g_rows, self.g_cols, self.n_in)
        self.g_src, self.g_slot, self.g_gam, self.g_fac = g_src[perm], g_slot[perm], g_gam[perm], g_fac[perm]
        self.g_is_cbf = self.g_slot < m
        self._g_src_cbf = self.g_src[self.g_is_cbf]
        self._g_slot_cbf = self.g_slot[self.g_is_cbf]
        self._g_src_work = self.g_src.copy()
        self._act: bytes | None = None  # slots whose DCBF entries are in _g_src_work
        self._gamma: float | None = None
        self._g_mult = self.g_fac.copy()
        # rows of the DCBF constraints (for the near-activity test)
        self.cbf_rows = (np.arange(n_h)[:, None] * nr + self.row_cbf + np.arange(m)[None, :]).ravel()
        self.solver: Any = None
        self.backend = cfg.qp_solver
        self.osqp_mat: Any = None

    def fill_matrices(self, flat: np.ndarray, act: np.ndarray, gamma: float) -> None:
        """Write the values of A and G (CSC data, fixed pattern) from the flat linearisation buffer."""
        # mode="clip": numpy buffers `out` for the default mode="raise"; the indices are in range by
        # construction, so the clipping never applies
        flat.take(self.a_src, out=self.A.data, mode="clip")
        self.A.data *= self.a_fac
        src = self._g_src_work
        if self.m:
            key = act.tobytes()
            if key != self._act:
                src[self.g_is_cbf] = self._g_src_cbf + 3 * act[self._g_slot_cbf]
                self._act = key
        flat.take(src, out=self.G.data, mode="clip")
        if gamma != self._gamma:
            self._g_mult = self.g_fac + (1.0 - gamma) * self.g_gam
            self._gamma = gamma
        self.G.data *= self._g_mult

    def _csc(self, rows: np.ndarray, cols: np.ndarray, n_rows: int):
        order = np.lexsort((rows, cols))  # column-major
        r_sorted, c_sorted = rows[order], cols[order]
        if np.any((np.diff(c_sorted) == 0) & (np.diff(r_sorted) == 0)):
            raise RuntimeError("duplicate entries in the QP pattern")  # construction bug
        indptr = np.zeros(self.nz + 1, dtype=np.int64)
        np.add.at(indptr, c_sorted + 1, 1)
        indptr = np.cumsum(indptr)
        mat = sp.csc_matrix((np.ones(len(order)), r_sorted.astype(np.int64), indptr), shape=(n_rows, self.nz))
        return mat, order


# --------------------------------------------------------------------------------------
# The controller
# --------------------------------------------------------------------------------------


class MPCDCBF:
    """MPC-DCBF solved by an SQP real-time iteration (see the module docstring).

    Typical loop::

        mpc = MPCDCBF(MPCConfig())
        s_pred = mpc.predicted_s(v0=x[3]) + s_ego          # where to evaluate the track
        stage = MPCStageData(kappa=track.kappa(s_pred), n_ref=..., v_ref=...,
                             n_min=-track.width_right(s_pred), n_max=track.width_left(s_pred))
        res = mpc.solve(np.array([0, n, e, v, delta]), stage, opponents_rel, gamma)
        plant.step(..., res.u)
    """

    def __init__(self, config: MPCConfig = MPCConfig(), vehicle: VehicleParams = AV21):
        import casadi as ca

        self.config = config
        self.vehicle = vehicle
        cfg = config
        self._n = n_h = cfg.horizon
        self._m_max = cfg.max_opponents
        self._m_slots = max(cfg.max_opponents, 1)  # the stage function has at least one slot
        self._t = cfg.time_grid()
        self._dts = np.diff(self._t)
        name = "sofar_mpc_stage_" + _definition_hash(
            vehicle, cfg.barrier, self._m_slots, cfg.integrator_substeps, ca.__version__)
        stage_fn = _stage_function(vehicle, cfg.barrier, self._m_max, cfg.integrator_substeps, name)
        # batched evaluation over the N+1 stages: the map itself is compiled (one C call per
        # linearisation, no per-stage dispatch through CasADi: 20 instead of 30 us)
        k1 = n_h + 1
        mapped, info = compile_function(stage_fn.map(f"{name}_x{k1}", "serial", k1, [], []), cfg.cache_dir,
                                        cfg.compile)
        self.codegen_info: CodegenInfo = info
        """How the linearisation is evaluated (compiled C or CasADi), and whether it was built now."""
        a_sp = stage_fn.sparsity_out(1).get_triplet()
        b_sp = stage_fn.sparsity_out(2).get_triplet()
        self._a_sp = (np.asarray(a_sp[0]), np.asarray(a_sp[1]))
        self._b_sp = (np.asarray(b_sp[0]), np.asarray(b_sp[1]))
        self._nnz_a = len(a_sp[0])
        self._nnz_b = len(b_sp[0])

        # evaluation into pre-allocated arrays
        self._mapped = mapped
        ms = self._m_slots
        self._in_x = np.zeros((k1, 5))
        self._in_u = np.zeros((k1, 2))
        self._in_kappa = np.zeros(k1)
        self._in_dt = np.concatenate([self._dts, [cfg.ts]])
        self._in_o = np.zeros((k1, ms, 3))
        self._in_o[:] = _DUMMY_OPPONENT  # unused slots: finite dummies, their outputs are discarded
        self._n_opp_filled = 0  # slots holding real opponents (the others hold the dummy)
        self._out_f = np.zeros((k1, 5))
        lay = _Layout(slots=ms, nnz_a=self._nnz_a, nnz_b=self._nnz_b, stages=k1,
                      lat_scale=1.0 / math.sqrt(cfg.lat_acc_slack[1]), trk_scale=1.0 / math.sqrt(cfg.track_slack[1]),
                      cbf_scale=1.0 / math.sqrt(cfg.barrier_slack[1]))
        self._layout = lay
        self._flat = np.zeros(lay.size)  # constants + A, B, dalat, dh of all stages (outputs write into it)
        self._flat[: lay.n_const] = lay.constants()
        self._out_a = self._flat[lay.off_a:lay.off_b].reshape(k1, self._nnz_a)
        self._out_b = self._flat[lay.off_b:lay.off_dal].reshape(k1, self._nnz_b)
        self._out_dalat = self._flat[lay.off_dal:lay.off_dh].reshape(k1, 2)
        self._out_dh = self._flat[lay.off_dh:].reshape(k1, ms, 3)
        self._out_alat = np.zeros(k1)
        self._out_h = np.zeros((k1, ms))
        buf, self._eval = mapped.buffer()
        for i, arr in enumerate((self._in_x, self._in_u, self._in_kappa, self._in_dt, self._in_o)):
            buf.set_arg(i, memoryview(arr))
        for i, arr in enumerate((self._out_f, self._out_a, self._out_b, self._out_alat, self._out_dalat,
                                 self._out_h, self._out_dh)):
            buf.set_res(i, memoryview(arr))
        self._buf = buf  # keeps the buffer (and its pointers into the arrays above) alive

        self._qp: dict[tuple, _QPStructure] = {}
        # linearisation point and references per QP block (du_k, dx_{k+1}): x7 = (ubar_k, xbar_{k+1}),
        # ref7 = (0, 0, 0, n_ref_{k+1}, 0, v_ref_{k+1}, 0) (written by _assemble)
        self._x7 = np.zeros((n_h, _N_FIXED))
        self._ref7 = np.zeros((n_h, _N_FIXED))
        self._d7 = np.zeros((n_h, _N_FIXED))
        self._box_lo = np.full((n_h, _N_FIXED), -np.inf)  # box on (du_k, dx_{k+1}) at the current iterate
        self._box_hi = np.full((n_h, _N_FIXED), np.inf)
        # the box itself, one row per stage: box_lo = lo7 - x7, box_hi = hi7 - x7 (-0.0 - v is -v to
        # the last bit, also for v = 0; +-inf minus a finite value stays +-inf)
        p = vehicle
        self._lo7 = np.tile([p.a_min, -p.steer_rate_max, -np.inf, -np.inf, -np.inf, -0.0, -p.steer_max], (n_h, 1))
        self._hi7 = np.tile([p.a_max, p.steer_rate_max, np.inf, np.inf, np.inf, np.inf, p.steer_max], (n_h, 1))
        self._drop_lo7 = np.tile(-_BOX_DROP_DISTANCE, (n_h, 1))  # -/+ _BOX_DROP_DISTANCE per stage
        self._drop_hi7 = np.tile(_BOX_DROP_DISTANCE, (n_h, 1))
        self._box_mask = np.zeros((n_h, _N_FIXED), dtype=bool)
        self._trk_lo = np.zeros(n_h)  # bounds on dn_{k+1} of the track rows (without slack)
        self._trk_hi = np.zeros(n_h)
        self._w_lat = np.zeros((n_h, 2))  # work arrays of _rows_violated
        self._w_n = np.zeros((2, n_h))
        self._w_box = np.zeros((2, n_h, _N_FIXED))
        self.n_row_resolves = 0  # QPs re-solved because a left-out row was violated (diagnostics)
        self._act = np.zeros(0, dtype=np.intp)  # slots with QP rows in the current solve
        self._nlp: dict[int, Any] = {}
        # shift of the warm start: precomputed interpolation weights
        self._shift_setup()
        self.n_failures = 0
        """Number of failed solves since construction or the last reset()."""
        self.reset()

    # ---------------------------------------------------------------- warm start

    def _shift_setup(self) -> None:
        """Precompute the shift as one matrix: x_guess = W @ x_plan (linear interpolation in time,
        linear extrapolation past t_N), and the zero-order-hold input indices."""
        t = self._t
        n_h = self._n
        cfg = self.config
        t_ext = t[-1] + max(cfg.control_dt, cfg.ts) + cfg.ts
        ratio = (t_ext - t[-1]) / (t[-1] - t[-2])
        extend = np.zeros((n_h + 2, n_h + 1))  # x_plan -> (x_plan, extrapolated point)
        extend[: n_h + 1, : n_h + 1] = np.eye(n_h + 1)
        extend[n_h + 1, n_h] = 1.0 + ratio
        extend[n_h + 1, n_h - 1] = -ratio
        te = np.concatenate([t, [t_ext]])
        q = t + cfg.control_dt
        j = np.clip(np.searchsorted(te, q, side="right") - 1, 0, n_h)
        w = (q - te[j]) / (te[j + 1] - te[j])
        interp = np.zeros((n_h + 1, n_h + 2))
        interp[np.arange(n_h + 1), j] = 1.0 - w
        interp[np.arange(n_h + 1), j + 1] += w
        self._shift_w = interp @ extend
        self._shift_ju = np.clip(np.searchsorted(t, q[:-1] + 1e-9, side="right") - 1, 0, n_h - 1)

    def reset(self) -> None:
        """Forget the warm start and zero the failure counter."""
        self._xg: np.ndarray | None = None  # (N+1, 5) guess for the next solve, s re-anchored
        self._ug: np.ndarray | None = None  # (N, 2)
        self._plan_age = 0  # consecutive fallbacks since the last successful plan
        self.n_failures = 0

    def predicted_s(self, v0: float | None = None) -> np.ndarray:
        """(N+1,) arc lengths of the warm start, relative to the ego at the next solve [m].

        Evaluate the track (curvature, edges, references) at these points plus the
        ego's absolute s. Without a plan (before the first solve, after reset() or a
        brake fallback) the guess is constant speed ``v0`` [m/s] (None: 0).
        """
        if self._xg is not None:
            return self._xg[:, 0].copy()
        return max(float(v0 or 0.0), 0.0) * self._t

    def _cold_guess(self, x0: np.ndarray, opponents: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Guess without a previous plan: constant speed and lateral offset, but never driving
        through an opponent that is ahead in the ego's lane (the guess then stays ``a0`` behind
        it). A guess that crosses an opponent linearises the barrier near its centre, where its
        gradient vanishes, and the first QP becomes badly conditioned."""
        v0 = max(float(x0[3]), 0.0)
        t = self._t
        s = v0 * t
        if opponents is not None and len(opponents):
            bp = self.config.barrier
            ahead = (opponents[:, 0] > 0.0) & (np.abs(opponents[:, 1] - x0[1]) < bp.b)
            if np.any(ahead):
                o = opponents[ahead]
                cap = (o[None, :, 0] + o[None, :, 2] * t[:, None] - bp.a0).min(axis=1)
                s = np.maximum.accumulate(np.clip(np.minimum(s, cap), 0.0, None))
        xg = np.zeros((self._n + 1, 5))
        xg[:, 0] = s
        xg[:, 1] = x0[1]
        xg[1:, 3] = np.diff(s) / np.diff(t)
        xg[0, 3] = v0
        u = np.zeros((self._n, 2))
        u[:, 0] = np.clip(np.diff(xg[:, 3]) / np.diff(t), self.vehicle.a_min, self.vehicle.a_max)
        return xg, u

    def _shift(self, xs: np.ndarray, us: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Plan (xs, us) shifted by control_dt and re-anchored at s = 0."""
        xg = self._shift_w @ xs
        ug = us[self._shift_ju]
        p = self.vehicle
        xg[:, 0] -= xg[0, 0]
        np.minimum(np.maximum(xg[:, 4], -p.steer_max, out=xg[:, 4]), p.steer_max, out=xg[:, 4])
        np.maximum(xg[:, 3], 0.0, out=xg[:, 3])
        return xg, ug

    # ---------------------------------------------------------------- validation

    def _validate(self, x0, stage, opponents, gamma):
        """Checked copies of the arguments; ValueError for malformed ones."""
        n_h = self._n
        try:
            gamma = float(gamma)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"gamma must be a real number, got {gamma!r}") from exc
        if not (math.isfinite(gamma) and 0.0 <= gamma <= 1.0):
            raise ValueError(f"gamma must be finite and in [0, 1], got {gamma!r}")
        x0 = np.array(x0, dtype=float).reshape(-1)
        if x0.shape != (5,) or not math.isfinite(float(x0.sum())):
            raise ValueError(f"x0 must be 5 finite values (s, n, e, v, delta), got {x0!r}")
        x0[0] = 0.0
        if not isinstance(stage, MPCStageData):
            raise ValueError("stage must be an MPCStageData")
        try:
            arrays = np.array([stage.kappa, stage.n_ref, stage.v_ref, stage.n_min, stage.n_max], dtype=float)
        except ValueError as exc:
            raise ValueError(f"stage arrays must all have {n_h + 1} values") from exc
        if arrays.shape != (5, n_h + 1) or not math.isfinite(float(arrays.sum())):
            raise ValueError(f"stage arrays must be {n_h + 1} finite values each, got shape {arrays.shape}")
        opp = np.asarray(opponents, dtype=float)
        if opp.size == 0:
            opp = np.zeros((0, 3))
        if opp.ndim != 2 or opp.shape[1] != 3 or not math.isfinite(float(opp.sum())):
            raise ValueError(f"opponents must be an (M, 3) array of finite (s_rel, n, v), got shape {opp.shape}")
        return x0, arrays, opp, gamma

    # ---------------------------------------------------------------- opponents

    def _select_opponents(self, opp: np.ndarray, xg: np.ndarray) -> np.ndarray:
        """Up to max_opponents rows: inside the gap window, smallest barrier along the guess."""
        cfg = self.config
        if len(opp) == 0 or self._m_max == 0:
            return opp[:0]
        mask = (opp[:, 0] >= -cfg.opponent_range_behind) & (opp[:, 0] <= cfg.opponent_range_ahead)
        cand = opp[mask]
        if len(cand) > self._m_max:
            t = self._t[:, None]
            o = np.stack([cand[None, :, 0] + cand[None, :, 2] * t,
                          np.broadcast_to(cand[None, :, 1], (len(t), len(cand))),
                          np.broadcast_to(cand[None, :, 2], (len(t), len(cand)))], axis=-1)
            hmin = barrier(xg[:, None, :], o, cfg.barrier).min(axis=0)
            cand = cand[np.argsort(hmin, kind="stable")[: self._m_max]]
        return cand

    def _fill_opponents(self, sel: np.ndarray) -> None:
        m = len(sel)
        o = self._in_o
        if m:
            t = self._t[:, None]
            np.multiply(sel[:, 2], t, out=o[:, :m, 0])
            o[:, :m, 0] += sel[:, 0]
            o[:, :m, 1] = sel[:, 1]
            o[:, :m, 2] = sel[:, 2]
        if m < self._n_opp_filled:
            o[:, m:self._n_opp_filled, :] = _DUMMY_OPPONENT
        self._n_opp_filled = m

    def _relevant_slots(self, n_cand: int, gamma: float) -> np.ndarray:
        """Slots (of the filled candidates) that get DCBF rows in the QP.

        A candidate is left out only when, along the warm start, its barrier stays above
        ``opponent_h_keep`` and every DCBF row is inactive by more than
        ``opponent_dcbf_keep``: one RTI step moves the first predicted state by
        centimetres, so the first transition still satisfies the DCBF for it, and it
        is reconsidered at the next solve. Uses the linearisation outputs (no extra cost).
        """
        if n_cand == 0:
            return np.zeros(0, dtype=np.intp)
        cfg = self.config
        h = self._out_h[:, :n_cand]
        resid = (1.0 - gamma) * h[:-1] - h[1:]
        keep = (h.min(axis=0) < cfg.opponent_h_keep) | (resid.max(axis=0) > -cfg.opponent_dcbf_keep)
        return keep.nonzero()[0]

    # ---------------------------------------------------------------- QP

    def _structure(self, m: int, lat: bool = True, trk: bool = True) -> _QPStructure:
        key = (m, lat, trk)
        qs = self._qp.get(key)
        if qs is None:
            qs = _QPStructure(self.config, self.vehicle, m, lat, trk, self._a_sp, self._b_sp, self._layout)
            self._qp[key] = qs
        return qs

    def _rows_needed(self, xbar: np.ndarray, arrays: np.ndarray) -> list[bool]:
        """Which of [lateral-acceleration rows, track rows, all box bounds] the QP at this
        linearisation starts with.

        The rows are left out when the linearisation point keeps away from them at every
        stage (by ``_LAT_ROWS_MARGIN``, ``_TRK_ROWS_MARGIN``), and each box bound when the
        linearisation point is farther from it than ``_BOX_DROP_DISTANCE`` (see
        :meth:`_assemble`); the QP solution is then checked against what was left out
        (:meth:`_rows_violated`) and the QP re-solved with it when violated (for the box:
        with every bound of each violated column). A constraint that holds (with zero
        slack) at the optimum of the smaller QP leaves that optimum unchanged, so the
        answer is the same either way; the smaller QP needs fewer interior-point
        iterations, each cheaper.
        """
        if self.config.qp_solver != "piqp":
            # OSQP's solutions (eps 1e-4) miss the 1e-6 check often: re-solves cost more than they save
            return [True, True, True]
        lat = np.abs(self._out_alat[1:]).max() > self.vehicle.lat_acc_max - _LAT_ROWS_MARGIN
        trk = self._trk_hi.min() < _TRK_ROWS_MARGIN or self._trk_lo.max() > -_TRK_ROWS_MARGIN
        return [bool(lat), bool(trk), False]

    def _track_bounds(self, xbar: np.ndarray, arrays: np.ndarray) -> None:
        """Bounds on dn_{k+1} of the track rows without slack, at this linearisation."""
        cfg = self.config
        nbar = xbar[1:, 1]
        np.subtract(arrays[4, 1:] - cfg.track_margin, nbar, out=self._trk_hi)
        np.subtract(arrays[3, 1:] + cfg.track_margin, nbar, out=self._trk_lo)

    def _rows_violated(self, qs: _QPStructure, box_dist: np.ndarray | None, zz: np.ndarray, xbar: np.ndarray,
                       arrays: np.ndarray) -> tuple[bool, bool, np.ndarray | None]:
        """Left-out constraints that the QP solution ``zz`` violates: (lateral-acceleration rows,
        track rows, None or the columns of the box (as in ``_BOX_DROP_DISTANCE``) with a violated bound)."""
        lat = trk = False
        box = None
        if not qs.lat:
            w = self._w_lat
            np.multiply(self._out_dalat[1:], zz[:, 5:7], out=w)
            alat = w.sum(axis=1)
            alat += self._out_alat[1:]
            np.abs(alat, out=alat)
            lat = alat.max() > self.vehicle.lat_acc_max + _ROWS_CHECK_TOL
        if not qs.trk:  # the track rows' bounds on dn were written by _assemble
            w = self._w_n
            np.subtract(zz[:, 3], self._trk_hi, out=w[0])
            np.subtract(self._trk_lo, zz[:, 3], out=w[1])
            trk = w.max() > _ROWS_CHECK_TOL
        if box_dist is not None:
            w = self._w_box
            np.subtract(self._box_lo, zz[:, :_N_FIXED], out=w[0])
            np.subtract(zz[:, :_N_FIXED], self._box_hi, out=w[1])
            worst = w.max(axis=(0, 1))
            if worst.max() > _ROWS_CHECK_TOL:
                box = worst > _ROWS_CHECK_TOL
        return bool(lat), bool(trk), box

    def _linearise(self, xbar: np.ndarray, ubar: np.ndarray, kappa: np.ndarray) -> None:
        self._in_x[:] = xbar
        self._in_u[:-1] = ubar
        self._in_u[-1] = 0.0
        self._in_kappa[:] = kappa
        self._eval()

    def _assemble(self, qs: _QPStructure, xbar, ubar, arrays, gamma, box_dist: np.ndarray | None = None):
        """QP vectors (c, b, h_l, h_u, x_l, x_u) in the buffers of ``qs``; A and G are written in place.
        ``box_dist``: None (every box bound), or per column of (du_k, dx_{k+1}) the distance from
        the linearisation point beyond which a bound is left out (see :meth:`_rows_needed`)."""
        p = self.vehicle
        # cost: c = 2 R ubar, 2 Q (xbar - xref), slack L1 weights (constant); computed per block as
        # w7 * (x7 - ref7) (subtracting the zeros of ref7 leaves every value as it is)
        x7, ref7 = self._x7, self._ref7
        x7[:, 0:2] = ubar
        x7[:, 2:7] = xbar[1:]
        ref7[:, 3] = arrays[1, 1:]
        ref7[:, 5] = arrays[2, 1:]
        np.subtract(x7, ref7, out=self._d7)
        np.multiply(qs.w7, self._d7, out=qs.c7)
        # matrices: one gather each from the flat linearisation buffer
        qs.fill_matrices(self._flat, self._act, gamma)
        np.subtract(self._out_f[:-1], xbar[1:], out=qs.b_buf)
        if qs.lat:
            alat = self._out_alat[1:]
            np.subtract(p.lat_acc_max, alat, out=qs.hu_lat)
            np.subtract(-p.lat_acc_max, alat, out=qs.hl_lat)
        if qs.trk:  # bounds computed by _track_bounds at this linearisation
            qs.hu_trk[:] = self._trk_hi
            qs.hl_trk[:] = self._trk_lo
        if qs.m:
            h = self._out_h.take(self._act, axis=1)
            np.subtract(h[1:], (1.0 - gamma) * h[:-1], out=qs.hu_cbf)
        # variable bounds (du_k, dx_{k+1}) in the full box, then in the QP's buffers
        lo, hi = self._box_lo, self._box_hi
        np.subtract(self._lo7, x7, out=lo)
        np.subtract(self._hi7, x7, out=hi)
        xl, xu = qs.xl7, qs.xu7
        xl[:] = lo
        xu[:] = hi
        if box_dist is not None:
            if box_dist is _BOX_DROP_DISTANCE:
                drop_lo, drop_hi = self._drop_lo7, self._drop_hi7
            else:
                drop_lo, drop_hi = -box_dist, box_dist
            mask = self._box_mask
            np.copyto(xl, -np.inf, where=np.less(lo, drop_lo, out=mask))
            np.copyto(xu, np.inf, where=np.greater(hi, drop_hi, out=mask))
        return qs.data

    def _qp_solve(self, qs: _QPStructure, data) -> tuple[np.ndarray | None, int, str]:
        """(z or None, iterations, message); the matrices are already in qs.A / qs.G."""
        c, b, hl, hu, xl, xu = data
        # every linearisation output enters one of these sums (a NaN or inf anywhere shows up)
        total = b.sum() + c.sum() + qs.A.data.sum() + qs.G.data.sum() + self._out_alat.sum()
        if qs.m:
            total += self._out_h[:, self._act].sum()
        if not math.isfinite(float(total)):
            return None, 0, "non-finite QP data"
        if (xl > xu).any():
            return None, 0, "inconsistent hard bounds"
        try:
            if qs.backend == "piqp":
                z, iters, status = self._solve_piqp(qs, data)
            else:
                z, iters, status = self._solve_osqp(qs, data)
        except (RuntimeError, ValueError, ArithmeticError) as exc:
            qs.solver = None  # set up afresh next time
            return None, 0, f"{qs.backend} raised {exc}"
        if z is None:
            qs.solver = None  # a fresh set-up (and scaling) next time
            return None, iters, status
        if not math.isfinite(float(z.sum())):
            return None, iters, f"{qs.backend} returned non-finite values"
        return z, iters, "solved"

    def _solve_piqp(self, qs: _QPStructure, data):
        piqp = _import_piqp()
        c, b, hl, hu, xl, xu = data
        cfg = self.config
        if qs.solver is None:
            solver = piqp.SparseSolver()
            st = solver.settings
            st.verbose = False
            st.eps_abs = cfg.qp_eps_abs
            st.eps_rel = cfg.qp_eps_rel
            st.check_duality_gap = False
            st.preconditioner_scale_cost = True  # without it some cold-start QPs stall
            # The QP is feasible and bounded by construction (soft constraints, consistent boxes,
            # R > 0, Z > 0; checked before the call); PIQP's infeasibility tests misfire on it.
            st.eps_primal_inf = 1e-12
            st.eps_dual_inf = 1e-12
            # the data change little from step to step: keeping the first scaling saves ~130 us per update
            st.preconditioner_reuse_on_update = True
            st.max_iter = cfg.qp_max_iter
            solver.setup(qs.P, c, qs.A, b, qs.G, hl, hu, xl, xu)
            qs.solver = solver
        else:
            qs.solver.update(c=c, A=qs.A, b=b, G=qs.G, h_l=hl, h_u=hu, x_l=xl, x_u=xu)
        status = qs.solver.solve()
        res = qs.solver.result
        iters = int(res.info.iter)
        if status != piqp.PIQP_SOLVED:
            return None, iters, f"piqp status {status}"
        return np.array(res.x), iters, "solved"

    def _solve_osqp(self, qs: _QPStructure, data):
        import osqp

        c, b, hl, hu, xl, xu = data
        big = 1e20  # OSQP's infinity is 1e30; clip the infinite bounds below it
        lo = np.concatenate([b, np.maximum(hl, -big), np.maximum(xl, -big)])
        up = np.concatenate([b, np.minimum(hu, big), np.minimum(xu, big)])
        mat = sp.vstack([qs.A, qs.G, sp.identity(qs.nz, format="csc")], format="csc")
        if qs.solver is None or qs.osqp_mat is None or mat.nnz != qs.osqp_mat.nnz:
            solver = osqp.OSQP()
            solver.setup(sp.triu(qs.P, format="csc"), c, mat, lo, up, verbose=False, eps_abs=1e-4,
                         eps_rel=1e-4, max_iter=4000, polishing=False, warm_starting=True)
            qs.solver = solver
            qs.osqp_mat = mat
        else:
            qs.solver.update(q=c, l=lo, u=up, Ax=mat.data)
        res = qs.solver.solve(raise_error=False)
        iters = int(res.info.iter)
        if res.info.status_val not in (osqp.SolverStatus.OSQP_SOLVED, osqp.SolverStatus.OSQP_SOLVED_INACCURATE):
            return None, iters, f"osqp status {res.info.status}"
        return np.array(res.x), iters, "solved"

    # ---------------------------------------------------------------- solve

    def solve(self, x0, stage: MPCStageData, opponents, gamma: float) -> MPCResult:
        """One real-time iteration (see the module docstring). Never raises for numerical trouble.

        ``x0 = (0, n, e, v, delta)`` (s is taken as 0); ``opponents`` (M, 3) rows
        ``(s_rel, n, v)`` at time 0, any M >= 0; ``gamma`` in [0, 1].
        """
        t_start = time.perf_counter()
        x0, arrays, opp, gamma = self._validate(x0, stage, opponents, gamma)
        cfg = self.config
        n_h = self._n
        p = self.vehicle
        dt0 = float(self._dts[0])
        if abs(x0[4]) > p.steer_max + dt0 * p.steer_rate_max or x0[3] < -dt0 * p.a_max:
            # the hard bounds on delta_1 (or v_1 >= 0) cannot be met: the QP would be infeasible
            bmin = float(barrier(x0[None, :], opp, cfg.barrier).min()) if len(opp) else math.inf
            return self._fallback(x0, "state outside the reach of the hard bounds", t_start, 0, 0, bmin, 0)
        cold = self._xg is None
        if cold:
            xbar, ubar = self._cold_guess(x0, opp)
        else:
            xbar, ubar = self._xg.copy(), self._ug.copy()
        xbar[0] = x0
        sel = self._select_opponents(opp, xbar)
        n_cand = len(sel)
        self._fill_opponents(sel)
        kappa = arrays[0]
        self._linearise(xbar, ubar, kappa)
        # stage 0 is x0 against the opponents at t = 0
        barrier_min = float(self._out_h[0, :n_cand].min()) if n_cand else math.inf
        act = self._relevant_slots(n_cand, gamma)
        m = len(act)
        self._act = act
        if cold:  # new situation: set the QP solvers up afresh (their scaling is reused until then)
            for qs in self._qp.values():
                qs.solver = None

        n_iter = cfg.cold_start_iterations if cold else 1
        qp_iters = 0
        sqp_iters = 0
        qp_time = 0.0
        z = None
        message = ""
        while True:
            if sqp_iters > 0:
                self._linearise(xbar, ubar, kappa)
            self._track_bounds(xbar, arrays)
            lat, trk, all_boxes = self._rows_needed(xbar, arrays)
            box_dist = None if all_boxes else _BOX_DROP_DISTANCE
            while True:
                qs = self._structure(m, lat, trk)
                data = self._assemble(qs, xbar, ubar, arrays, gamma, box_dist)
                t_qp = time.perf_counter()
                z, it, message = self._qp_solve(qs, data)
                qp_time += time.perf_counter() - t_qp
                qp_iters += it
                if z is None:
                    break
                zz = z.reshape(n_h, qs.nb)
                add_lat, add_trk, add_box = self._rows_violated(qs, box_dist, zz, xbar, arrays)
                if not (add_lat or add_trk or add_box is not None):
                    break
                # solve again with the violated kind of constraint (for the box: its violated columns)
                lat, trk = lat or add_lat, trk or add_trk
                if add_box is not None:
                    box_dist = np.where(add_box, np.inf, box_dist)
                self.n_row_resolves += 1
            sqp_iters += 1
            if z is None:
                break
            xbar[1:] += zz[:, 2:7]
            ubar += zz[:, 0:2]
            if sqp_iters < n_iter:
                continue
            if (sqp_iters == n_iter and m and cfg.extra_iteration_when_active
                    and self._barrier_near_active(qs, z, data[3])):
                continue
            break

        if len(opp) > n_cand:  # opponents outside the window: evaluate h numerically
            # barrier(x0[None, :], opp) without its argument checks
            h_all = barrier_expr(x0[0:1], x0[1:2], x0[3:4], opp[:, 0], opp[:, 1], opp[:, 2], cfg.barrier)
            barrier_min = min(barrier_min, float(h_all.min()))
        if z is None or not math.isfinite(float(xbar.sum() + ubar.sum())):
            return self._fallback(x0, message or "non-finite iterate", t_start, qp_iters, sqp_iters,
                                  barrier_min, m)

        zz = z.reshape(n_h, qs.nb)
        slack = {
            "lat_acc": float(max(zz[:, qs.col_lat].max() * qs.slack_scale[0], 0.0)) if qs.lat else 0.0,
            "track": float(max(zz[:, qs.col_trk].max() * qs.slack_scale[int(qs.lat)], 0.0)) if qs.trk else 0.0,
            "barrier": 0.0,
        }
        first = 0.0
        if m:  # slacks in their physical units
            sig = zz[:, qs.col_cbf:] * qs.slack_scale[-1]
            slack["barrier"] = float(max(sig.max(), 0.0))
            first = float(max(sig[0].max(), 0.0))
        p = self.vehicle
        u = np.array([min(max(ubar[0, 0], p.a_min), p.a_max),
                      min(max(ubar[0, 1], -p.steer_rate_max), p.steer_rate_max)])
        x_pred, u_pred = xbar.copy(), ubar.copy()
        self._xg, self._ug = self._shift(xbar, ubar)
        self._plan_age = 0
        return MPCResult(u=u, x_pred=x_pred, u_pred=u_pred, status=STATUS_SOLVED, success=True, slack=slack,
                         barrier_min=barrier_min, solve_time=time.perf_counter() - t_start,
                         qp_iterations=qp_iters, sqp_iterations=sqp_iters, barrier_slack_first=first,
                         n_opponents=m, qp_time=qp_time)

    def _barrier_near_active(self, qs: _QPStructure, z: np.ndarray, hu: np.ndarray) -> bool:
        """Is any linearised DCBF row within barrier_active_tol of its bound at the QP solution?"""
        rows = qs.cbf_rows
        if qs.backend == "piqp":
            margin = qs.solver.result.s_u[rows]  # h_u - G z, as computed by PIQP
        else:
            margin = hu[rows] - (qs.G @ z)[rows]
        return bool(margin.min() < self.config.barrier_active_tol)

    def _fallback(self, x0, message, t_start, qp_iters, sqp_iters, barrier_min, m) -> MPCResult:
        cfg = self.config
        p = self.vehicle
        self.n_failures += 1
        self._plan_age += 1
        horizon_time = self._t[-1]
        if self._xg is not None and self._plan_age * max(cfg.control_dt, cfg.ts) < horizon_time:
            status = STATUS_FALLBACK_SHIFT
            x_pred, u_pred = self._xg.copy(), self._ug.copy()
            u = np.array([min(max(u_pred[0, 0], p.a_min), p.a_max),
                          min(max(u_pred[0, 1], -p.steer_rate_max), p.steer_rate_max)])
            self._xg, self._ug = self._shift(x_pred, u_pred)
        else:
            status = STATUS_FALLBACK_BRAKE
            period = cfg.control_dt if cfg.control_dt > 0.0 else cfg.ts
            u = np.array([0.5 * p.a_min, min(max(-x0[4] / period, -p.steer_rate_max), p.steer_rate_max)])
            x_pred, u_pred = self._cold_guess(x0)
            u_pred[:] = u
            self._xg, self._ug = None, None
        logger.debug("MPC solve failed (%s); %s, failure #%d", message, status, self.n_failures)
        return MPCResult(u=u, x_pred=x_pred, u_pred=u_pred, status=status, success=False,
                         slack={"lat_acc": 0.0, "track": 0.0, "barrier": 0.0}, barrier_min=barrier_min,
                         solve_time=time.perf_counter() - t_start, qp_iterations=qp_iters,
                         sqp_iterations=sqp_iters, barrier_slack_first=0.0, n_opponents=m)

    # ---------------------------------------------------------------- IPOPT reference

    def _build_nlp(self, m: int):
        import casadi as ca

        cfg = self.config
        p = self.vehicle
        n_h = self._n
        nb = _N_FIXED + 2 + m
        w = ca.SX.sym("w", n_h * nb)
        x0 = ca.SX.sym("x0", 5)
        kappa = ca.SX.sym("kappa", n_h + 1)
        nref = ca.SX.sym("nref", n_h + 1)
        vref = ca.SX.sym("vref", n_h + 1)
        nmin = ca.SX.sym("nmin", n_h + 1)
        nmax = ca.SX.sym("nmax", n_h + 1)
        opp = ca.SX.sym("opp", 3 * m * (n_h + 1))
        gamma = ca.SX.sym("gamma")
        par = ca.vertcat(x0, kappa, nref, vref, nmin, nmax, opp, gamma)
        ops = _casadi_ops()
        q, r = cfg.q, cfg.r

        def blk(k):
            return w[k * nb:(k + 1) * nb]

        def opp_k(k, i):
            base = 3 * (k * m + i)
            return opp[base], opp[base + 1], opp[base + 2]

        def hfun(x, k, i):
            so, no, vo = opp_k(k, i)
            return barrier_expr(x[0], x[1], x[3], so, no, vo, cfg.barrier, ops)

        cost = 0
        g, lbg, ubg = [], [], []
        x_prev = x0
        for k in range(n_h):
            b = blk(k)
            u = b[0:2]
            x = b[2:7]
            sl, st = b[7], b[8]
            xs = [x_prev[i] for i in range(5)]
            f = rk4_step(lambda xx, uu: frenet_rhs(xx, uu, kappa[k], p, ca), xs, [u[0], u[1]],
                         float(self._dts[k]), cfg.integrator_substeps)
            g.append(x - ca.vertcat(*f))
            lbg += [0.0] * 5
            ubg += [0.0] * 5
            alat = lateral_acceleration(x[3], x[4], p, ca)
            g += [alat - sl, alat + sl, x[1] - st - (nmax[k + 1] - cfg.track_margin),
                  x[1] + st - (nmin[k + 1] + cfg.track_margin)]
            lbg += [-ca.inf, -p.lat_acc_max, -ca.inf, 0.0]
            ubg += [p.lat_acc_max, ca.inf, 0.0, ca.inf]
            for i in range(m):
                g.append((1.0 - gamma) * hfun(x_prev, k, i) - hfun(x, k + 1, i) - b[9 + i])
                lbg.append(-ca.inf)
                ubg.append(0.0)
            ref = [0.0, nref[k + 1], 0.0, vref[k + 1], 0.0]
            cost += sum(q[j] * (x[j] - ref[j]) ** 2 for j in range(5) if q[j] != 0.0)
            cost += r[0] * u[0] ** 2 + r[1] * u[1] ** 2
            cost += cfg.lat_acc_slack[0] * sl + 0.5 * cfg.lat_acc_slack[1] * sl ** 2
            cost += cfg.track_slack[0] * st + 0.5 * cfg.track_slack[1] * st ** 2
            for i in range(m):
                cost += cfg.barrier_slack[0] * b[9 + i] + 0.5 * cfg.barrier_slack[1] * b[9 + i] ** 2
            x_prev = x
        nlp = {"x": w, "p": par, "f": cost, "g": ca.vertcat(*g)}
        opts = {"print_time": False, "ipopt.print_level": 0, "ipopt.sb": "yes", "ipopt.tol": 1e-10,
                "ipopt.constr_viol_tol": 1e-10, "ipopt.max_iter": 1000}
        solver = ca.nlpsol(f"sofar_mpc_ipopt_{m}", "ipopt", nlp, opts)
        return solver, np.array(lbg, dtype=float), np.array(ubg, dtype=float)

    def solve_converged(self, x0, stage: MPCStageData, opponents, gamma: float) -> MPCResult:
        """The same NLP solved to convergence with IPOPT (validation reference, ~10-100 ms).

        Same arguments, result and failure handling as :meth:`solve`; the solution also
        becomes the warm start of the next call.
        """
        t_start = time.perf_counter()
        x0, arrays, opp, gamma = self._validate(x0, stage, opponents, gamma)
        p = self.vehicle
        n_h = self._n
        if self._xg is None:
            xbar, ubar = self._cold_guess(x0)
        else:
            xbar, ubar = self._xg.copy(), self._ug.copy()
        xbar[0] = x0
        sel = self._select_opponents(opp, xbar)
        m = len(sel)
        if m not in self._nlp:
            self._nlp[m] = self._build_nlp(m)
        solver, lbg, ubg = self._nlp[m]
        nb = _N_FIXED + 2 + m
        t = self._t[:, None]
        o = np.zeros((n_h + 1, m, 3))
        if m:
            o[:, :, 0] = sel[None, :, 0] + sel[None, :, 2] * t
            o[:, :, 1] = sel[None, :, 1]
            o[:, :, 2] = sel[None, :, 2]
        par = np.concatenate([x0, arrays.ravel(), o.ravel(), [gamma]])
        w0 = np.zeros((n_h, nb))
        w0[:, 0:2] = ubar
        w0[:, 2:7] = xbar[1:]
        lbx = np.full((n_h, nb), -np.inf)
        ubx = np.full((n_h, nb), np.inf)
        lbx[:, 0], ubx[:, 0] = p.a_min, p.a_max
        lbx[:, 1], ubx[:, 1] = -p.steer_rate_max, p.steer_rate_max
        lbx[:, 5] = 0.0
        lbx[:, 6], ubx[:, 6] = -p.steer_max, p.steer_max
        lbx[:, 7:] = 0.0
        w0 = np.clip(w0, lbx, ubx)
        barrier_min = float(barrier(x0[None, :], opp, self.config.barrier).min()) if len(opp) else math.inf
        try:
            sol = solver(x0=w0.ravel(), p=par, lbx=lbx.ravel(), ubx=ubx.ravel(), lbg=lbg, ubg=ubg)
            stats = solver.stats()
            ok = bool(stats.get("success", False))
            iters = int(stats.get("iter_count", 0))
            z = np.array(sol["x"]).reshape(-1)
        except RuntimeError as exc:
            ok, iters, z = False, 0, None
            stats = {"return_status": str(exc)}
        if not ok or z is None or not np.all(np.isfinite(z)):
            return self._fallback(x0, f"ipopt: {stats.get('return_status')}", t_start, iters, 1, barrier_min, m)
        zz = z.reshape(n_h, nb)
        xs = np.vstack([x0, zz[:, 2:7]])
        us = zz[:, 0:2].copy()
        slack = {"lat_acc": float(max(zz[:, 7].max(), 0.0)), "track": float(max(zz[:, 8].max(), 0.0)),
                 "barrier": float(max(zz[:, 9:].max(), 0.0)) if m else 0.0}
        first = float(max(zz[0, 9:].max(), 0.0)) if m else 0.0
        u = np.clip(us[0], [p.a_min, -p.steer_rate_max], [p.a_max, p.steer_rate_max])
        self._xg, self._ug = self._shift(xs, us)
        self._plan_age = 0
        return MPCResult(u=u, x_pred=xs, u_pred=us, status=STATUS_SOLVED, success=True, slack=slack,
                         barrier_min=barrier_min, solve_time=time.perf_counter() - t_start,
                         qp_iterations=iters, sqp_iterations=1, barrier_slack_first=first, n_opponents=m)
