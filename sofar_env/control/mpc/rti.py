"""The MPC-DCBF controller, :class:`MPCDCBF`: one SQP real-time iteration per solve.

Real-time iteration
-------------------
One QP per :meth:`MPCDCBF.solve` (Gauss-Newton SQP, full step), linearised at the
previous solution shifted in time by ``control_dt`` (:mod:`.warmstart`). When a barrier
constraint is near-active in the QP solution (``extra_iteration_when_active``) a second
iteration re-linearises at the new iterate: with an opponent close, one RTI step keeps
less distance than the converged solution. A cold start (first solve, after
:meth:`MPCDCBF.reset` or a brake fallback) runs ``cold_start_iterations`` iterations.
The linearisation is one compiled C call (:mod:`.linearisation`), the QP matrices are
gathered into a fixed pattern (:mod:`.layout`) and solved by PIQP, by DAQP after condensing
(:mod:`.condensed`) or by OSQP (:mod:`.backends`). :meth:`MPCDCBF.solve_converged` solves the very same NLP to
convergence with IPOPT, for validation (:mod:`.reference`).

QP size (PIQP backend). Constraints far from the linearisation point are left out of
the QP and checked afterwards: the lateral-acceleration rows when ``|a_lat|`` stays 3 m/s^2
below its bound at every stage, the track rows when ``n`` stays 0.5 m inside the
margined edges (never with ``track_rows = "ends"``: those rows are always in), and each box bound (on ``a``, ``delta_dot``, ``v >= 0``, ``delta``)
farther than a fixed distance from the linearisation point. When the solution
violates a left-out constraint (by more than 1e-6), the QP is solved again with it.
A constraint that holds at the optimum of the smaller QP leaves that optimum
unchanged (it is also the optimum of the QP with the constraint, whose slack is
then zero), so the answer is that of the full QP. The gain is mostly in
interior-point iterations: far-away bounds (above all ``v >= 0`` at racing speed) cost
PIQP about 4 of its 10 iterations. Each pattern (number of opponent slots with rows,
presence of the lateral-acceleration and of the track rows) gets its own solver
instance.

Opponents: of the given rows, those inside the gap window
``[-opponent_range_behind, opponent_range_ahead]`` are candidates; if there are more
than ``max_opponents``, those with the smallest barrier along the warm start win
(:func:`~.model.select_opponents`). A candidate gets no QP rows when its barrier stays
above ``opponent_h_keep`` along the warm start and all its DCBF rows are inactive there
by more than ``opponent_dcbf_keep`` (:func:`~.model.relevant_slots`); this keeps the QP
small when opponents are far.

Restart
-------
An RTI linearises the barrier along the previous plan. When that plan passes an opponent on
one side, the linearised barrier pushes the next plan further to that side, even after the
lateral reference has moved to the other side (the passing-side planner changed its mind,
or the opponent moved across): the QP then satisfies its DCBF rows only with slack, and
the car keeps going where the old plan went. With ``restart_slack`` finite, a warm-started
solve whose largest DCBF slack exceeds it is solved once more from the cold guess
(constant lateral offset, never through an opponent ahead; ``cold_start_iterations``
iterations), and the solution with the smaller slack (by at least ``_RESTART_GAIN``) is
kept; otherwise the warm-started solution and its warm start stand. Restarts are counted
in ``n_restarts`` and ``n_restarts_taken``.

Failure handling: a solver status other than solved, or a non-finite number
anywhere, never raises. The controller returns the first control of the shifted
previous plan (``status = "fallback_shift"``) while that plan still covers the
horizon, else a safe brake ``a = a_min / 2`` with the steering rate driving delta
towards 0 (``"fallback_brake"``). Failures are counted in ``n_failures`` and logged
at debug level. ``ValueError`` is raised only for malformed arguments.
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, replace

import numpy as np

from ...configs.mpc import BarrierParams
from ...vehicle import AV21, VehicleParams
from ..barrier import barrier_table
from ..codegen import CodegenInfo
from .assembly import STATUS_INCONSISTENT, STATUS_NONFINITE, all_finite, assemble, track_rows, violated_rows
from .backends import FALLBACK_SOLVED, dcbf_margin, solve_qp
from .ends import EndOffsets
from .layout import N_FIXED, QPStructure
from .linearisation import StageLinearisation
from .model import relevant_slots, select_opponents, variable_box
from .reference import IpoptReference, ReferenceSolution
from .types import (STATUS_FALLBACK_BRAKE, STATUS_FALLBACK_SHIFT, STATUS_SOLVED, MPCConfig, MPCResult,
                    MPCStageData, validate_arguments)
from .warmstart import PlanShift, cold_guess

__all__ = ["MPCDCBF", "DeferredBarrierMin"]

logger = logging.getLogger(__name__)

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
# A restart's solution replaces the warm-started one when its largest DCBF slack is smaller by this [-]
_RESTART_GAIN = 1e-3


@dataclass(frozen=True)
class DeferredBarrierMin:
    """``h``, or ``min(partial, h)``, with ``h`` the smallest barrier value of the state ``x0`` (5,) against the
    opponent rows ``opponents`` (M >= 1, 3 or 4) by :func:`~sofar_env.control.barrier.barrier_table`, evaluated
    when called: :attr:`MPCResult.barrier_min <.types.MPCResult.barrier_min>` of a solve. The arrays are the
    solve's own copies."""

    partial: float | None
    x0: np.ndarray
    opponents: np.ndarray
    params: BarrierParams

    @classmethod
    def of(cls, x0: np.ndarray, opponents: np.ndarray, params: BarrierParams,
           partial: float | None = None) -> DeferredBarrierMin | float:
        """The deferred value; without opponents ``partial`` (inf if None) at once."""
        if not len(opponents):
            return math.inf if partial is None else partial
        return cls(partial, x0.copy(), opponents.copy(), params)

    def __call__(self) -> float:
        h = barrier_table(self.x0[None, :], self.opponents[None, :, :3], self.params)[2]
        return h if self.partial is None else min(self.partial, h)


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
        self.config = config
        self.vehicle = vehicle
        self._n = config.horizon
        self._t = config.time_grid()
        self._dts = np.diff(self._t)
        self._lin = StageLinearisation(config, vehicle, self._dts)
        self.codegen_info: CodegenInfo = self._lin.codegen_info
        """How the linearisation is evaluated (compiled C or CasADi), and whether it was built now."""
        self._qp: dict[tuple, QPStructure] = {}
        # the end rows' offsets, unless the track rows bound the reference point
        self._end_offsets = EndOffsets.for_rows(config.track_rows, vehicle)
        self._box = variable_box(vehicle)  # hard bounds on (u_k, x_{k+1})
        self._u_lo = self._box[0][:2].tolist()  # the hard input bounds, as floats (_clip_input)
        self._u_hi = self._box[1][:2].tolist()
        self._box_lo = self._box_hi = None  # the box on (du_k, dx_{k+1}) at the current iterate
        self._trk_lo = np.empty(self._n)  # bounds on dn_{k+1} of the track rows (without slack)
        self._trk_hi = np.empty(self._n)
        self._rows_near = (True, True)  # the lateral-acceleration and track rows are needed (_track_bounds)
        self._act = np.zeros(0, dtype=np.intp)  # slots with QP rows in the current solve
        self._shift = PlanShift(config, vehicle)
        self._reference: IpoptReference | None = None  # built by the first solve_converged()
        self.n_row_resolves = 0
        """QPs re-solved because a left-out row or bound was violated (diagnostics)."""
        self.n_failures = 0
        """Number of failed solves since construction or the last reset()."""
        self.n_restarts = 0
        """Restarts from a cold guess since construction or the last reset() (``restart_slack``)."""
        self.n_restarts_taken = 0
        """Restarts whose solution was kept, since construction or the last reset()."""
        self.n_qp_fallbacks = 0
        """QPs the backend failed on and ``qp_fallback`` solved, since construction (not zeroed by reset())."""
        self.reset()

    # ---------------------------------------------------------------- warm start

    def reset(self) -> None:
        """Forget the warm start and zero the failure counter."""
        self._xg: np.ndarray | None = None  # (N+1, 5) guess for the next solve, s re-anchored
        self._ug: np.ndarray | None = None  # (N, 2)
        self._plan_age = 0  # consecutive fallbacks since the last successful plan
        self.n_failures = 0
        self.n_restarts = 0
        self.n_restarts_taken = 0

    def predicted_s(self, v0: float | None = None) -> np.ndarray:
        """(N+1,) arc lengths of the warm start, relative to the ego at the next solve [m].

        Evaluate the track (curvature, edges, references) at these points plus the
        ego's absolute s. Without a plan (before the first solve, after reset() or a
        brake fallback) the guess is constant speed ``v0`` [m/s] (None: 0).
        """
        if self._xg is not None:
            return self._xg[:, 0].copy()
        return max(float(v0 or 0.0), 0.0) * self._t

    def _guess(self, x0: np.ndarray, opponents: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        """Linearisation point of the first iteration: the shifted plan, or a cold guess."""
        if self._xg is None:
            xbar, ubar = cold_guess(x0, self._t, self.vehicle, self.config.barrier, opponents)
        else:
            xbar, ubar = self._xg.copy(), self._ug.copy()
        xbar[0] = x0
        return xbar, ubar

    def _clip_input(self, u: np.ndarray) -> np.ndarray:
        """(a, delta_dot) clipped to the hard input bounds: ``np.clip`` on floats (min(max(.)) propagates
        a nan as np.clip does; the bounds are not 0, so no signed-zero tie)."""
        a, d = u.tolist()
        lo, hi = self._u_lo, self._u_hi
        return np.array([min(max(a, lo[0]), hi[0]), min(max(d, lo[1]), hi[1])])

    # ---------------------------------------------------------------- solve

    def solve(self, x0, stage: MPCStageData, opponents, gamma: float) -> MPCResult:
        """One real-time iteration (see the module docstring). Never raises for numerical trouble.

        ``x0 = (0, n, e, v, delta)`` (s is taken as 0); ``opponents`` (M, 3) rows
        ``(s_rel, n, v)`` at time 0, or (M, 4) rows ``(s_rel, n, v, n_dot)`` of opponents that also move
        across the track at ``n_dot``, any M >= 0; ``gamma`` in [0, 1].
        """
        t_start = time.perf_counter()
        x0, arrays, opp, gamma = validate_arguments(x0, stage, opponents, gamma, self._n)
        warm = self._xg is not None
        result = self._solve(x0, arrays, opp, gamma, t_start)
        if warm and result.success and result.slack["barrier"] > self.config.restart_slack:
            result = self._restart(x0, arrays, opp, gamma, t_start, result)
        return result

    def _restart(self, x0, arrays, opp, gamma, t_start, result: MPCResult) -> MPCResult:
        """The solve once more from a cold guess (module docstring, "Restart"); the better of the two."""
        kept = (self._xg, self._ug, self._plan_age, self.n_failures)
        self._xg = self._ug = None
        self.n_restarts += 1
        fresh = self._solve(x0, arrays, opp, gamma, t_start)
        if fresh.success and fresh.slack["barrier"] < result.slack["barrier"] - _RESTART_GAIN:
            self.n_restarts_taken += 1
            return fresh
        self._xg, self._ug, self._plan_age, self.n_failures = kept
        return replace(result, solve_time=time.perf_counter() - t_start)

    def _solve(self, x0, arrays, opp, gamma, t_start) -> MPCResult:
        """One real-time iteration on validated arguments (:meth:`solve`)."""
        cfg = self.config
        p = self.vehicle
        dt0 = float(self._dts[0])
        if abs(x0[4]) > p.steer_max + dt0 * p.steer_rate_max or x0[3] < -dt0 * p.a_max:
            # the hard bounds on delta_1 (or v_1 >= 0) cannot be met: the QP would be infeasible
            bmin = DeferredBarrierMin.of(x0, opp, cfg.barrier)
            return self._fallback(x0, "state outside the reach of the hard bounds", t_start, 0, 0, bmin, 0)
        cold = self._xg is None
        xbar, ubar = self._guess(x0, opp)
        lin = self._lin
        sel = select_opponents(opp, xbar, self._t, cfg)
        n_cand = len(sel)
        lin.set_opponents(sel, self._t)
        kappa = arrays[0]
        lin.evaluate(xbar, ubar, kappa)
        # stage 0 is x0 against the opponents at t = 0
        barrier_min = float(lin.h[0, :n_cand].min()) if n_cand else math.inf
        act = relevant_slots(lin.h[:, :n_cand], gamma, cfg)
        m = len(act)
        self._act = act
        if cold:  # new situation: set the QP solvers up afresh (their scaling is reused until then)
            for qs in self._qp.values():
                qs.drop_solver()

        n_iter = cfg.cold_start_iterations if cold else 1
        qp_iters = 0
        sqp_iters = 0
        qp_time = 0.0
        fallbacks = self.n_qp_fallbacks
        z = None
        message = ""
        while True:
            if sqp_iters > 0:
                lin.evaluate(xbar, ubar, kappa)
            self._track_bounds(xbar, arrays)
            lat, trk, all_boxes = self._rows_needed(xbar, arrays)
            box_dist = None if all_boxes else _BOX_DROP_DISTANCE
            while True:
                qs = self._structure(m, lat, trk)
                data, status = self._assemble(qs, xbar, ubar, arrays, gamma, box_dist)
                t_qp = time.perf_counter()
                z, it, message = self._qp_solve(qs, data, status)
                qp_time += time.perf_counter() - t_qp
                qp_iters += it
                if z is None:
                    break
                zz = z.reshape(self._n, qs.nb)
                add_lat, add_trk, add_box = self._rows_violated(qs, box_dist, zz)
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
                    and dcbf_margin(qs, z, data[3]).min() < cfg.barrier_active_tol):
                continue
            break

        if len(opp) > n_cand:  # opponents outside the window: evaluate h numerically
            barrier_min = DeferredBarrierMin.of(x0, opp, cfg.barrier, barrier_min)
        if z is None or not (all_finite(xbar) and all_finite(ubar)):
            return self._fallback(x0, message or "non-finite iterate", t_start, qp_iters, sqp_iters,
                                  barrier_min, m)

        zz = z.reshape(self._n, qs.nb)
        slack = {
            "lat_acc": float(max(zz[:, qs.col_lat].max() * qs.slack_scale[0], 0.0)) if qs.lat else 0.0,
            "track": float(max(_track_violation(qs, zz).max(), 0.0)) if qs.trk else 0.0,
            "barrier": 0.0,
        }
        first = 0.0
        if m:  # slacks in their physical units
            sig = zz[:, qs.col_cbf:] * qs.slack_scale[-1]
            slack["barrier"] = float(max(sig.max(), 0.0))
            first = float(max(sig[0].max(), 0.0))
        x_pred, u_pred = xbar.copy(), ubar.copy()
        self._xg, self._ug = self._shift(xbar, ubar)
        self._plan_age = 0
        return MPCResult(u=self._clip_input(ubar[0]), x_pred=x_pred, u_pred=u_pred, status=STATUS_SOLVED,
                         success=True, slack=slack, h_now=barrier_min,
                         solve_time=time.perf_counter() - t_start, qp_iterations=qp_iters,
                         sqp_iterations=sqp_iters, barrier_slack_first=first, n_opponents=m, qp_time=qp_time,
                         qp_fallbacks=self.n_qp_fallbacks - fallbacks)

    def _fallback(self, x0, message, t_start, qp_iters, sqp_iters, barrier_min, m) -> MPCResult:
        cfg = self.config
        p = self.vehicle
        self.n_failures += 1
        self._plan_age += 1
        if self._xg is not None and self._plan_age * max(cfg.control_dt, cfg.ts) < self._t[-1]:
            status = STATUS_FALLBACK_SHIFT
            x_pred, u_pred = self._xg.copy(), self._ug.copy()
            u = self._clip_input(u_pred[0])
            self._xg, self._ug = self._shift(x_pred, u_pred)
        else:
            status = STATUS_FALLBACK_BRAKE
            period = cfg.control_dt if cfg.control_dt > 0.0 else cfg.ts
            u = self._clip_input(np.array([0.5 * p.a_min, -x0[4] / period]))
            x_pred, u_pred = cold_guess(x0, self._t, p, cfg.barrier)
            u_pred[:] = u
            self._xg, self._ug = None, None
        logger.debug("MPC solve failed (%s); %s, failure #%d", message, status, self.n_failures)
        return MPCResult(u=u, x_pred=x_pred, u_pred=u_pred, status=status, success=False,
                         slack={"lat_acc": 0.0, "track": 0.0, "barrier": 0.0}, h_now=barrier_min,
                         solve_time=time.perf_counter() - t_start, qp_iterations=qp_iters,
                         sqp_iterations=sqp_iters, barrier_slack_first=0.0, n_opponents=m)

    # ---------------------------------------------------------------- QP

    def _structure(self, m: int, lat: bool = True, trk: bool = True) -> QPStructure:
        key = (m, lat, trk)
        qs = self._qp.get(key)
        if qs is None:
            lin = self._lin
            qs = QPStructure(self.config, m, lat, trk, lin.a_sparsity, lin.b_sparsity, lin.layout,
                             end_offsets=self._end_offsets)
            self._qp[key] = qs
        return qs

    def _rows_needed(self, xbar: np.ndarray, arrays: np.ndarray) -> list[bool]:
        """Which of [lateral-acceleration rows, track rows, all box bounds] the QP at this
        linearisation starts with (module docstring, "QP size").

        The rows are left out when the linearisation point keeps away from them at every
        stage (by ``_LAT_ROWS_MARGIN``, ``_TRK_ROWS_MARGIN``), each box bound when the
        linearisation point is farther from it than ``_BOX_DROP_DISTANCE``; what was left
        out is checked by :meth:`_rows_violated` (for the box: per column).
        """
        if self.config.qp_solver != "piqp":
            # OSQP's solutions (eps 1e-4) miss the 1e-6 check often: re-solves cost more than they save;
            # DAQP (active set) solves the full QP: rows far from activity cost it little
            return [True, True, True]
        return [*self._rows_near, False]

    def _track_bounds(self, xbar: np.ndarray, arrays: np.ndarray) -> None:
        """Bounds on dn_{k+1} of the track rows without slack, at this linearisation (the
        :func:`~.model.track_limits` minus ``n``), and whether the lateral-acceleration and the track rows
        are near (:meth:`_rows_needed`); one compiled call (:func:`.assembly.track_rows`)."""
        lat, trk = track_rows(arrays, self.config.track_margin, xbar, self._lin.alat,
                              self.vehicle.lat_acc_max - _LAT_ROWS_MARGIN, _TRK_ROWS_MARGIN, self._trk_lo, self._trk_hi)
        self._rows_near = (lat, trk or self._end_offsets is not None)  # the end rows are always included

    def _rows_violated(self, qs: QPStructure, box_dist: np.ndarray | None,
                       zz: np.ndarray) -> tuple[bool, bool, np.ndarray | None]:
        """Left-out constraints that the QP solution ``zz`` violates: (lateral-acceleration rows,
        track rows, None or the columns of the box (as in ``_BOX_DROP_DISTANCE``) with a violated bound);
        one compiled call (:func:`.assembly.violated_rows`)."""
        lin = self._lin
        box = np.empty(N_FIXED, dtype=np.bool_)
        lat, trk, any_box = violated_rows(zz, not qs.lat, lin.dalat, lin.alat, self.vehicle.lat_acc_max,
                                          not qs.trk, self._trk_lo, self._trk_hi, self._box_lo, self._box_hi,
                                          box_dist is not None, _ROWS_CHECK_TOL, box)
        return lat, trk, (box if any_box else None)

    def _assemble(self, qs: QPStructure, xbar, ubar, arrays, gamma, box_dist: np.ndarray | None = None):
        """QP vectors (c, b, h_l, h_u, x_l, x_u) in the buffers of ``qs`` and the values of A and G, in one
        compiled call (:func:`.assembly.assemble`); returns ``(data, status)``. ``box_dist``: None (every box
        bound), or per column of (du_k, dx_{k+1}) the distance from the linearisation point beyond which a
        bound is left out (see :meth:`_rows_needed`)."""
        lin = self._lin
        n = self._n
        if self._box_lo is None:
            self._box_lo, self._box_hi = np.empty((n, N_FIXED)), np.empty((n, N_FIXED))
        status = assemble(
            (xbar, ubar), (arrays[1, 1:], arrays[2, 1:]), qs.w7,
            (self._box[0], self._box[1], box_dist is not None, _BOX_DROP_DISTANCE if box_dist is None else box_dist),
            (lin.flat, lin.f, lin.alat, lin.h), (qs.a_src, qs.a_fac, qs.A.data),
            (qs.g_src, qs.g_slot, qs.g_gam, qs.g_fac, qs.G.data), (self._act, float(gamma)),
            (qs.lat, qs.row_lat, self.vehicle.lat_acc_max, qs.trk, qs.row_trk, self._trk_lo, self._trk_hi, qs.row_cbf),
            (qs.c_buf, qs.b_buf, qs.hl_buf, qs.hu_buf, qs.xl_buf, qs.xu_buf), (self._box_lo, self._box_hi))
        if qs.ends:
            qs.fill_ends(xbar[1:, 2], self._trk_lo, self._trk_hi, arrays[0, 1:])
        return qs.data(), status

    def _qp_solve(self, qs: QPStructure, data, status: int) -> tuple[np.ndarray | None, int, str]:
        """(z or None, iterations, message); ``status`` of the assembly (:func:`.assembly.assemble`)."""
        if status == STATUS_NONFINITE:
            return None, 0, "non-finite QP data"
        if status == STATUS_INCONSISTENT:
            return None, 0, "inconsistent hard bounds"
        z, iters, message = solve_qp(qs, data, self.config)
        self.n_qp_fallbacks += message == FALLBACK_SOLVED
        return z, iters, message

    # ---------------------------------------------------------------- IPOPT reference

    def solve_converged(self, x0, stage: MPCStageData, opponents, gamma: float) -> MPCResult:
        """The same NLP solved to convergence with IPOPT (validation reference, ~10-100 ms).

        Same arguments, result and failure handling as :meth:`solve`; the solution also
        becomes the warm start of the next call.
        """
        t_start = time.perf_counter()
        cfg = self.config
        x0, arrays, opp, gamma = validate_arguments(x0, stage, opponents, gamma, self._n)
        xbar, ubar = self._guess(x0, None)
        sel, sol = self._reference_solve(x0, arrays, opp, gamma, xbar, ubar)
        m = len(sel)
        barrier_min = barrier_table(x0[None, :], opp[None, :, :3], cfg.barrier)[2] if len(opp) else math.inf
        if not sol.success:
            return self._fallback(x0, f"ipopt: {sol.message}", t_start, sol.iterations, 1, barrier_min, m)
        first = float(max(sol.slack_barrier[0].max(), 0.0)) if m else 0.0
        slack = {"lat_acc": float(max(sol.slack_lat_acc.max(), 0.0)), "track": float(max(sol.slack_track.max(), 0.0)),
                 "barrier": float(max(sol.slack_barrier.max(), 0.0)) if m else 0.0}
        self._xg, self._ug = self._shift(sol.x, sol.u)
        self._plan_age = 0
        return MPCResult(u=self._clip_input(sol.u[0]), x_pred=sol.x, u_pred=sol.u, status=STATUS_SOLVED,
                         success=True, slack=slack, h_now=barrier_min,
                         solve_time=time.perf_counter() - t_start, qp_iterations=sol.iterations,
                         sqp_iterations=1, barrier_slack_first=first, n_opponents=m)

    def reference_solution(self, x0, stage: MPCStageData, opponents, gamma: float,
                           guess: tuple[np.ndarray, np.ndarray] | None = None) -> ReferenceSolution:
        """IPOPT's solution of this step's NLP (as :meth:`solve_converged`) from ``guess`` = ((N+1, 5) states,
        (N, 2) inputs; None: the MPC's own warm start), with its objective (:class:`~.reference.ReferenceSolution`).
        The MPC is left as it was: its warm start and counters do not change. Raises ``ValueError`` for arguments
        :meth:`solve` refuses and for a guess of another shape."""
        x0, arrays, opp, gamma = validate_arguments(x0, stage, opponents, gamma, self._n)
        if guess is None:
            xbar, ubar = self._guess(x0, None)
        else:
            xbar, ubar = (np.array(a, dtype=float) for a in guess)
            if xbar.shape != (self._n + 1, 5) or ubar.shape != (self._n, 2):
                raise ValueError(f"guess must be ((N+1, 5), (N, 2)) = (({self._n + 1}, 5), ({self._n}, 2)) arrays, "
                                 f"got {xbar.shape} and {ubar.shape}")
            if not (all_finite(xbar) and all_finite(ubar)):
                raise ValueError("guess must be finite")
            xbar[0] = x0
        return self._reference_solve(x0, arrays, opp, gamma, xbar, ubar)[1]

    def _reference_solve(self, x0, arrays, opp, gamma, xbar, ubar) -> tuple[np.ndarray, ReferenceSolution]:
        """The opponents with DCBF rows and IPOPT's solution from ``(xbar, ubar)``."""
        sel = select_opponents(opp, xbar, self._t, self.config)
        if self._reference is None:
            self._reference = IpoptReference(self.config, self.vehicle, self._lin.stage)
        return sel, self._reference.solve(x0, arrays, sel, gamma, xbar, ubar)


def _track_violation(qs: QPStructure, zz: np.ndarray) -> np.ndarray:
    """(N,) violation of the track rows per stage [m]: the track slack, plus the buffer slack where there is one."""
    v = zz[:, qs.col_trk] * qs.slack_scale[int(qs.lat)]
    if qs.buf:
        v = v + zz[:, qs.col_buf] * qs.slack_scale[qs.col_buf - N_FIXED]
    return v
