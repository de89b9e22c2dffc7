"""Passing-side planner: a mixed-integer QP over a coarse lateral horizon.

This is the high-level overtaking decision of the paper (eq. ``miqp``): a lateral
offset profile ``d_k`` (relative to the raceline, Frenet ``n``) over a coarse
horizon, one binary side decision per group of relevant opponents, Big-M side
constraints with an L1-penalised slack, and deviation, smoothness and consistency
costs. :class:`PassingSidePlanner` assembles and solves it at every call and keeps
the previous plan and decisions; the parts live in their own modules:
:mod:`~sofar_env.planning.config` (parameters), :mod:`~sofar_env.planning.clearance`
(where and by how much each opponent must be cleared, and which opponents share a
side), :mod:`~sofar_env.planning.hysteresis` (the previous side of each car),
:mod:`~sofar_env.planning.problem` (the problem data and its exact cost),
:mod:`~sofar_env.planning.build` (all of the above from the inputs to the problem data, in one compiled call) and
:mod:`~sofar_env.planning.solvers` (DAQP branch-and-bound, enumeration fallback).

Problem solved at every :meth:`PassingSidePlanner.plan` call
------------------------------------------------------------
Unknowns: ``b_c in {0, 1}``, one binary per *cluster* of relevant opponents
(``b = 1``: pass on the left, ``d >= n_i + w_ik``; ``b = 0``: on the right,
``d <= n_i - w_ik``, with ``w_ik`` the clearance required at node k, ``safe_lat``
where the cars overlap); ``d_k``, the lateral offset at node ``k`` [m]; ``xi_p >=
0``, the slack of the side constraint of active pair ``p = (i, k)`` [m].

Cost::

    sum_k w_dev (d_k - n_ref_k)^2 + sum_k w_smooth (d_{k+1} - d_k)^2
    + sum_k w_prev (d_k - d_prev_k)^2                   (only with a previous plan)
    + sum_i w_switch (b_c(i) - b_prev_i)^2               (only with a previous side)
    + w_slack sum_p xi_p

``d_prev`` is the previous plan re-expressed at the new nodes (shifted by
``progress``, constant beyond its end). ``b_prev_i`` is the side chosen in the
previous call for the same car (see :mod:`~sofar_env.planning.hysteresis`). For
binary b, ``(b - b_prev)^2`` is linear.

Constraints:

* track (hard): ``n_min_k + track_margin <= d_k <= n_max_k - track_margin``;
  where the corridor is narrower than two margins it collapses to its centre;
* continuity (hard, never infeasible): ``|d_0 - e| <= continuity`` where ``e`` is
  the ego offset clipped into the node-0 corridor;
* side constraints (Big-M, soft through ``xi``) for every active pair ``(i, k)``;
* with ``alongside_gap`` > 0, the side lock: the binary of a cluster holding a car within
  ``alongside_gap`` of the ego along the track is fixed to the side of that car the ego is on now
  (left if the ego's offset is above the car's), unless the cluster holds cars alongside on both
  sides; two cars alongside on either side of the ego are never linked into one cluster.

The opponents are predicted at constant speed and offset, or along a given
prediction (``opponent_s``, e.g. the speed profile). An opponent with no active
pair is not relevant: side 0 and no variables. Without any relevant opponent the
plan is ``n_ref`` clipped into the corridor (status ``"no_opponents"``, no
continuity or smoothing applied), returned before any problem is built; with
``free_plan = "smooth"`` the problem above is solved without side constraints instead.
:attr:`PlanResult.opponent_slack` reports the violation per opponent (the stack's
pass-or-follow decision uses it). The reported objective is the cost above at the
returned ``(d, b)`` with the minimal slack, the same for both solver routes.
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass

import numpy as np

from .._interp import interp as _interp_kernel
from .build import NO_OPPONENTS, PROBLEM, UNBOUNDED, _corridor, build_problem, finish_plan
from .clearance import ClearanceWindow
from .config import MIQPConfig
from .hysteresis import prior_sides
from .problem import SideProblem, cost_factors, plan_cost
from .solvers import solve_branch_and_bound, solve_enumeration

__all__ = ["MIQPConfig", "PlanResult", "PassingSidePlanner"]

logger = logging.getLogger(__name__)

_EMPTY = np.zeros(0)
_NO_OPP = np.zeros((0, 3))
_NO_SIDES = np.zeros(0, dtype=np.int64)


@dataclass(frozen=True)
class PlanResult:
    """Outcome of one :meth:`PassingSidePlanner.plan` call."""

    d: np.ndarray
    """(nodes,) planned lateral offsets [m]."""
    s: np.ndarray
    """(nodes,) node arc lengths relative to the ego [m]."""
    sides: np.ndarray
    """(M,) int per input opponent: +1 pass left, -1 pass right, 0 not relevant."""
    objective: float
    """Cost of the returned plan (see the module docstring) [-]; nan on fallback."""
    status: str
    """"optimal", "no_opponents" or "fallback"."""
    success: bool
    """False only for a fallback plan."""
    solve_time: float
    """Wall time of plan() [s]."""
    n_binaries: int
    """Number of binary variables (side clusters) in the solved problem."""
    max_slack: float = 0.0
    """Largest side-constraint violation of the plan [m] (0: every clearance met)."""
    slack_sum: float = 0.0
    """Sum of the side-constraint violations over active pairs [m]."""
    opponent_slack: np.ndarray | None = None
    """(M,) largest side-constraint violation per input opponent [m] (0 for irrelevant ones;
    None on fallback)."""

    def lateral_at(self, s_query) -> np.ndarray:
        """Plan interpolated at relative arc lengths ``s_query`` [m], constant beyond the ends."""
        return _interp_kernel(np.asarray(s_query, dtype=float), self.s, self.d)  # np.interp


class PassingSidePlanner:
    """Chooses the passing side of every relevant opponent and a lateral plan.

    Stateful only through the previous plan and decisions (consistency and
    hysteresis terms); :meth:`reset` forgets them. Never raises inside
    :meth:`plan` on numerical trouble: it returns a fallback plan with
    ``success=False`` and increments :attr:`n_failures`.
    """

    def __init__(self, config: MIQPConfig = MIQPConfig()):
        self.config = config
        self._factors = cost_factors(config)  # Cholesky factors of the lateral cost (u = R d)
        self._window = ClearanceWindow(config)
        self._t = self._window.t  # node times [s]
        self._weights = (float(config.track_margin), float(config.continuity), float(config.w_dev),
                         float(config.w_prev), float(config.w_switch), float(config.alongside_gap),
                         float(config.cluster_gap), float(config.safe_lat), float(config.node_dt))
        self._window_args = self._window.arguments()  # the clearance table's parameters (build_problem's window)
        self._bnb_cache: dict = {}  # (C, P) -> Hessian, sense and index arrays of the branch-and-bound
        self.n_failures = 0
        self._prev_s: np.ndarray | None = None
        self._prev_d: np.ndarray | None = None
        self._prev_opp: np.ndarray | None = None
        self._prev_sides: np.ndarray | None = None

    # ------------------------------------------------------------------ state
    def reset(self) -> None:
        """Forget the previous plan and decisions, and zero the failure counter."""
        self._prev_s = None
        self._prev_d = None
        self._prev_opp = None
        self._prev_sides = None
        self.n_failures = 0

    def memory(self) -> tuple:
        """The previous plan and decisions (an opaque value for :meth:`restore_memory`)."""
        return (self._prev_s, self._prev_d, self._prev_opp, self._prev_sides)

    def restore_memory(self, memory: tuple) -> None:
        """Go back to the state returned by :meth:`memory` (e.g. to discard a trial plan)."""
        self._prev_s, self._prev_d, self._prev_opp, self._prev_sides = memory

    # ------------------------------------------------------------------- main
    def plan(self, s_nodes, n_ref, n_min, n_max, ego_n: float, opponents,
             progress: float = 0.0, opponent_s=None) -> PlanResult:
        """Plan the lateral offsets and passing sides.

        Args:
            s_nodes: (nodes,) ego arc length at the node times, relative to the ego
                (``s_nodes[0] = 0``), non-decreasing [m].
            n_ref: (nodes,) nominal lateral reference (usually 0, the raceline) [m].
            n_min: (nodes,) right edge, ``-width_right`` [m] (raw, margin applied here).
            n_max: (nodes,) left edge, ``+width_left`` [m].
            ego_n: current ego lateral offset [m].
            opponents: (M, 3) rows ``(s_rel, n, v)`` at time 0 [m, m, m/s], predicted
                at constant speed and offset. Rows may be reordered or filtered
                between calls: the hysteresis matches each opponent to the nearest
                (motion-propagated) opponent of the previous call.
            progress: metres the ego advanced since the previous call, used to
                re-express the previous plan at the new nodes [m].
            opponent_s: optional (M, nodes) predicted arc length of each opponent at the
                node times, relative to the ego now [m] (e.g. a prediction along the
                circuit's speed profile); None: constant speed, ``s_rel + v t``. The
                opponents' speeds for the closing-speed window are taken from it.

        Raises:
            ValueError: only for arrays of the wrong shape (a programming error).
        """
        t0 = time.perf_counter()
        cfg = self.config
        N = cfg.nodes
        s_nodes = np.asarray(s_nodes, dtype=float).reshape(-1)
        n_ref = np.asarray(n_ref, dtype=float).reshape(-1)
        n_min = np.asarray(n_min, dtype=float).reshape(-1)
        n_max = np.asarray(n_max, dtype=float).reshape(-1)
        for name, arr in (("s_nodes", s_nodes), ("n_ref", n_ref), ("n_min", n_min), ("n_max", n_max)):
            if arr.shape != (N,):
                raise ValueError(f"{name} must have shape ({N},), got {arr.shape}")
        opp = np.asarray(opponents, dtype=float)
        if opp.size == 0:
            opp = np.zeros((0, 3))
        if opp.ndim != 2 or opp.shape[1] != 3:
            raise ValueError(f"opponents must have shape (M, 3), got {opp.shape}")
        M = opp.shape[0]
        if opponent_s is None:
            opp_s = opp[:, :1] + opp[:, 2:3] * self._t[None, :]
        else:
            opp_s = np.asarray(opponent_s, dtype=float)
            if opp_s.size == 0 and M == 0:
                opp_s = np.zeros((0, N))
            if opp_s.shape != (M, N):
                raise ValueError(f"opponent_s must have shape ({M}, {N}), got {opp_s.shape}")

        ego_n, progress = float(ego_n), float(progress)
        nodes = (s_nodes, n_ref, n_min, n_max)
        try:
            status, lo, hi, relevant, parts = build_problem(nodes, opp, opp_s, (ego_n, progress), self._previous(),
                                                            self._weights, self._window_args, False)
            if status == UNBOUNDED:
                # Every input finite: its sum is (the sum of the old test, taken where a magnitude is too large).
                if not math.isfinite(s_nodes.sum() + n_ref.sum() + lo.sum() + hi.sum() + opp.sum() + opp_s.sum()
                                     + ego_n + progress):
                    return self._fallback(t0, s_nodes, n_ref, lo, hi, progress, opp, None, "non-finite input")
                status, lo, hi, relevant, parts = build_problem(nodes, opp, opp_s, (ego_n, progress),
                                                                self._previous(), self._weights, self._window_args,
                                                                True)
        except Exception as exc:  # numerical trouble while building: never raise
            lo, hi, _ = _corridor(n_min, n_max, float(cfg.track_margin), s_nodes, n_ref, opp, opp_s, ego_n, progress)
            return self._fallback(t0, s_nodes, n_ref, lo, hi, progress, opp, None, f"build failed: {exc!r}")
        if status == NO_OPPONENTS and cfg.free_plan == "smooth":
            parts = self._free_problem(s_nodes, n_ref, lo, hi, ego_n, progress)
            status = PROBLEM
        if status == NO_OPPONENTS:
            d = n_ref.clip(lo, hi)
            self._remember(s_nodes, d, opp, np.zeros(M, dtype=int))
            return PlanResult(d=d, s=s_nodes.copy(), sides=np.zeros(M, dtype=int),
                              objective=plan_cost(cfg, d, n_ref, None, 0.0, 0.0),
                              status="no_opponents", success=True,
                              solve_time=time.perf_counter() - t0, n_binaries=0,
                              opponent_slack=np.zeros(M))
        prob = self._problem(n_ref, parts)
        sol = None
        routes = ((self._solve_bnb, self._solve_enumerate) if cfg.solver == "daqp"
                  else (self._solve_enumerate,))
        for route in routes:  # branch-and-bound first, enumeration as its fallback
            try:
                sol = route(prob)
            except Exception as exc:
                sol = None
                logger.debug("MIQP route %s raised %r", route.__name__, exc)
            if sol is not None:
                break
        if sol is None:
            return self._fallback(t0, s_nodes, n_ref, lo, hi, progress, opp, prior_sides(relevant, prob.b_prev, M),
                                  "solver failed")
        # d clipped into the hard bounds (solver tolerance), slacks, sides: one compiled call (build.finish_plan)
        d, xi, switch, sides, opp_slack, max_slack = finish_plan(
            sol[0], sol[1], (prob.lo, prob.hi), (prob.pair_k, prob.pair_c, prob.pair_n, prob.pair_w, prob.pair_r),
            prob.rel_cluster, prob.b_prev, relevant, M)
        slack_sum = float(np.add.reduce(xi))
        obj = plan_cost(cfg, d, n_ref, prob.d_prev, cfg.w_switch * switch, cfg.w_slack * slack_sum)
        if not math.isfinite(obj):
            return self._fallback(t0, s_nodes, n_ref, lo, hi, progress, opp, prior_sides(relevant, prob.b_prev, M),
                                  "non-finite objective")
        self._remember(s_nodes, d, opp, sides)
        return PlanResult(d=d, s=s_nodes.copy(), sides=sides, objective=obj,
                          status="optimal", success=True,
                          solve_time=time.perf_counter() - t0, n_binaries=prob.n_clusters,
                          max_slack=max_slack, slack_sum=slack_sum, opponent_slack=opp_slack)

    # ------------------------------------------------------------ components
    def _previous(self) -> tuple:
        """The planner's memory as :func:`.build.build_problem` takes it: ``(has_plan, prev_s, prev_d, has_sides,
        prev_opp, prev_sides)``, empty arrays where there is none."""
        has_plan = self._prev_d is not None
        has_sides = self._prev_sides is not None and self._prev_opp is not None
        return (has_plan, self._prev_s if has_plan else _EMPTY, self._prev_d if has_plan else _EMPTY, has_sides,
                self._prev_opp if has_sides else _NO_OPP, self._prev_sides if has_sides else _NO_SIDES)

    def _free_problem(self, s_nodes: np.ndarray, n_ref: np.ndarray, lo: np.ndarray, hi: np.ndarray, ego_n: float,
                      progress: float) -> tuple:
        """The problem data of :func:`.build.build_problem` without a relevant opponent (``free_plan = "smooth"``):
        no cluster and no pair; node 0's continuity bounds, the previous plan at the new nodes and the linear
        cost as that function makes them."""
        cfg = self.config
        p_lo, p_hi = lo.copy(), hi.copy()
        e = min(max(ego_n, float(lo[0])), float(hi[0]))
        p_lo[0] = max(float(lo[0]), e - cfg.continuity)
        p_hi[0] = min(float(hi[0]), e + cfg.continuity)
        d_prev = _EMPTY
        f_d = -2.0 * cfg.w_dev * n_ref
        if self._prev_d is not None:
            d_prev = np.interp(s_nodes + progress, self._prev_s, self._prev_d)
            f_d = -2.0 * (cfg.w_dev * n_ref + cfg.w_prev * d_prev)
        none_i, none_f = np.zeros(0, dtype=np.int64), np.zeros(0)
        return (0, none_i, p_lo, p_hi, d_prev, f_d, none_i, none_f, none_i, none_i, none_i, none_f, none_f, none_i)

    def _problem(self, n_ref: np.ndarray, parts: tuple) -> SideProblem:
        """The :class:`SideProblem` of the data built by :func:`.build.build_problem` (``parts``): with the
        factors of the lateral cost (with the consistency term when there is a previous plan) and the
        incumbent's weights (``cfg.incumbent``)."""
        cfg = self.config
        C, labels, lo, hi, d_prev, f_d, b_prev, f_b, b_fixed, pair_k, pair_c, pair_n, pair_w, pair_r = parts
        has_plan = d_prev.shape[0] > 0
        Rinv, RinvT = self._factors[has_plan]
        w_diag = cfg.w_dev + (cfg.w_prev if has_plan else 0.0) if cfg.incumbent else None
        return SideProblem(lo=lo, hi=hi, f_d=f_d, Rinv=Rinv, RinvT=RinvT, pair_k=pair_k, pair_c=pair_c,
                           pair_n=pair_n, pair_w=pair_w, pair_r=pair_r, n_clusters=C, f_b=f_b, n_ref=n_ref,
                           d_prev=d_prev if has_plan else None, b_prev=b_prev, rel_cluster=labels,
                           b_fixed=b_fixed if b_fixed.shape[0] else None, w_diag=w_diag, w_smooth=cfg.w_smooth)

    # ------------------------------------------------------------- solvers
    def _solve_bnb(self, prob: SideProblem) -> tuple[np.ndarray, np.ndarray] | None:
        """DAQP branch-and-bound (its per-(C, P) set-up cached by this planner)."""
        return solve_branch_and_bound(prob, self.config.w_slack, self._bnb_cache, self.config.daqp_cycle_tol)

    def _solve_enumerate(self, prob: SideProblem) -> tuple[np.ndarray, np.ndarray] | None:
        """One QP per side pattern."""
        return solve_enumeration(prob, self.config.w_slack, self.config.daqp_cycle_tol)

    # ------------------------------------------------------------- helpers
    def _remember(self, s_nodes, d, opp, sides) -> None:
        """Keep this call's plan and decisions for the consistency and hysteresis terms."""
        self._prev_s = s_nodes.copy()
        self._prev_d = d.copy()
        self._prev_opp = opp.copy()
        self._prev_sides = sides.copy()

    def _fallback(self, t0, s_nodes, n_ref, lo, hi, progress, opp, prior, reason) -> PlanResult:
        """Previous plan shifted by ``progress`` (if any), else n_ref, clipped to the corridor."""
        self.n_failures += 1
        logger.warning("MIQP fallback (%s); failures so far: %d", reason, self.n_failures)
        M = opp.shape[0]
        s_out = np.nan_to_num(s_nodes, nan=0.0)
        shift = float(progress) if np.isfinite(progress) else 0.0
        d = None
        if self._prev_d is not None:
            d = np.interp(s_out + shift, self._prev_s, self._prev_d)
        if d is None or not np.all(np.isfinite(d)):
            d = np.nan_to_num(n_ref, nan=0.0, posinf=0.0, neginf=0.0)
        hi_f = np.nan_to_num(hi, nan=np.inf)
        lo_f = np.minimum(np.nan_to_num(lo, nan=-np.inf), hi_f)
        d = np.nan_to_num(np.clip(d, lo_f, hi_f), nan=0.0)
        sides = prior.copy() if prior is not None else np.zeros(M, dtype=int)
        if self._prev_d is not None:
            self._prev_d = d.copy()
            self._prev_s = s_out.copy()
        if prior is not None:
            self._prev_opp = opp.copy()
            self._prev_sides = sides.copy()
        return PlanResult(d=d, s=s_out.copy(), sides=sides, objective=float("nan"),
                          status="fallback", success=False,
                          solve_time=time.perf_counter() - t0, n_binaries=0)
