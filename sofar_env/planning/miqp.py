"""Passing-side planner: a mixed-integer QP over a coarse lateral horizon.

This is the high-level overtaking decision of the paper (eq. ``miqp``): a lateral
offset profile ``d_k`` (relative to the raceline, Frenet ``n``) over a coarse
horizon, one binary side decision per group of relevant opponents, Big-M side
constraints with an L1-penalised slack, and deviation, smoothness and consistency
costs.

Problem solved at every :meth:`PassingSidePlanner.plan` call
------------------------------------------------------------
Unknowns: ``b_c in {0, 1}``, one binary per *cluster* of relevant opponents
(``b = 1``: pass on the left, ``d >= n_i + safe_lat``; ``b = 0``: on the right,
``d <= n_i - safe_lat``); ``d_k``, the lateral offset at node ``k`` [m];
``xi_p >= 0``, the slack of the side constraint of active pair ``p = (i, k)`` [m].

Cost::

    sum_k w_dev (d_k - n_ref_k)^2 + sum_k w_smooth (d_{k+1} - d_k)^2
    + sum_k w_prev (d_k - d_prev_k)^2                   (only with a previous plan)
    + sum_i w_switch (b_c(i) - b_prev_i)^2               (only with a previous side)
    + w_slack sum_p xi_p

``d_prev`` is the previous plan re-expressed at the new nodes (shifted by
``progress``, constant beyond its end). ``b_prev_i`` is the side chosen in the
previous call for the same car, identified as the nearest previous opponent once
propagated at its speed (within ``cluster_gap`` along and ``safe_lat`` across the
track; otherwise no hysteresis). For binary b, ``(b - b_prev)^2`` is linear.

Constraints:

* track (hard): ``n_min_k + track_margin <= d_k <= n_max_k - track_margin``;
  where the corridor is narrower than two margins it collapses to its centre;
* continuity (hard, never infeasible): ``|d_0 - e| <= continuity`` where ``e`` is
  the ego offset clipped into the node-0 corridor;
* Big-M side constraints for every active pair ``(i, k)``::

      d_k <= n_i - safe_lat + Ma_ik * b + xi_ik
      d_k >= n_i + safe_lat - Mb_ik * (1 - b) - xi_ik

  with the tightest valid constants ``Ma_ik = max(0, hi_k - n_i + safe_lat)`` and
  ``Mb_ik = max(0, n_i + safe_lat - lo_k)`` (each is the smallest value that makes
  the relaxed row redundant inside the corridor ``[lo_k, hi_k]``). They are at most
  the track width plus ``safe_lat``, instead of the reference's 2000, which keeps
  the relaxations tight and the problem well conditioned.

Relevance and activation. With the longitudinal gap ``g_ik = s_i + v_i t_k -
s_nodes_k`` (opponent minus ego, opponents at constant speed and offset), the side
constraint of opponent i is imposed at *both* end nodes of every node interval on
which the linearly interpolated gap enters ``(-safe_lon, safe_lon)``, and at every
node inside it. Since the plan is itself linear between nodes, the clearance then
holds on the whole interpolated path whenever the cars overlap, whatever the node
spacing (6-12 m at 40-80 m/s, more against slow cars): no overlap can fall between
nodes, without having to inflate ``safe_lon``. An opponent with no active node is
not relevant: side 0 and no variables. Relevant opponents closer than
``cluster_gap`` to each other at a node where the ego overlaps either of them
share one binary (connected components), so the planner never threads between
them. Without any
relevant opponent the plan is ``n_ref`` clipped into the corridor (status
``"no_opponents"``, no continuity or smoothing applied).

Braking-distance window (``closing_decel > 0``; the stack sets it). The MPC's
barrier ellipse around an opponent is ``a0 + v_close^2 / (2 a_brake)`` long, so a
plan that crosses an opponent's lane inside that distance (typically: swinging
across right in front of a much slower car after passing another one) is one the
MPC can only follow by braking hard or using barrier slack. The window then
extends by ``L_ik = v_close,ik^2 / (2 closing_decel)`` on the side where the cars
close in, with a clearance tapering like the ellipse, ``safe_lat sqrt(1 - ((|g| -
safe_lon) / L)^2)``; node intervals are covered as above (each end node keeps the
largest clearance required on the interval). Beyond the box only every
``closing_stride``-th node is kept (solve time). The side constraints then use the
per-pair clearance ``w_ik`` in place of ``safe_lat``. The opponents' positions can
be given as a prediction (``opponent_s``, e.g. along the speed profile) instead of
constant speed. :attr:`PlanResult.opponent_slack` reports the violation per
opponent (the stack's pass-or-follow decision uses it).

Solvers. ``"daqp"`` uses DAQP's built-in branch-and-bound: binaries are simple
bounds ``0 <= b <= 1`` flagged binary (``sense`` 16). If it fails, the
enumeration below is tried before giving up. ``"enumerate"`` solves one QP per
side pattern (``2^C``, C <= 4 in practice) and keeps the best. Both are exact; the
reported objective is the cost above evaluated at the returned ``(d, b)`` with the
minimal slack (violations under 1e-6 m, i.e. solver tolerance, count as zero), so
the two routes are directly comparable.

Numerics. With ``H_d = R'R`` (Cholesky, computed once per planner), the solvers
work in ``u = R d``: DAQP then sees a *diagonal* Hessian, for which its set-up is
O(n) instead of a dense factorisation; ``d = R^-1 u`` enters through fixed rows.
DAQP needs a strictly positive-definite Hessian, so binaries get curvature
``_Q_BIN`` (cancelled exactly at 0/1 by a linear term, so the relaxation stays a
valid lower bound) and slacks a small curvature ``_Q_SLACK`` (a perturbation of
order 1e-7 of the objective when slack is used, none otherwise). Slacks start in
DAQP's working set at their bound (warm start), which saves one active-set
iteration per pair.

Per-call cost. The diagonal Hessian, the constraint types, the index arrays and the
constant parts of the bounds of the branch-and-bound depend only on ``(C, P)`` and are
cached per planner (as are the Cholesky factors and the coefficients of the
closing-speed derivative). The clearance window is evaluated for the nodes and node
intervals of all opponents at once (the arrays are small: the cost is the number of
numpy calls, not the number of opponents), and a call without any relevant opponent
returns before any problem is built.
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass

import numpy as np

from .._gradient import GridGradient
from .._interp import interp as _interp_kernel

try:  # DAQP is a hard dependency, but plan() must never raise because of it.
    import daqp
except ImportError:  # pragma: no cover - exercised only in broken installs
    daqp = None

__all__ = ["MIQPConfig", "PlanResult", "PassingSidePlanner"]

logger = logging.getLogger(__name__)

_INF = 1e30          # DAQP's notion of an infinite bound
_Q_BIN = 1.0         # curvature added to each binary; cancelled at 0/1 by a linear term
_Q_SLACK = 1e-2      # curvature added to each slack [1/m^2] (DAQP needs H > 0)
_DAQP_OK = (1, 2)    # DAQP exit flags that mean "optimal" (2: optimal with soft constraints)
_SLACK_TOL = 1e-6    # [m] violations below this are solver tolerance, not slack use
_SENSE_BINARY = 16
_SENSE_ACTIVE_LOWER = 3   # DAQP: ACTIVE (1) | LOWER (2): start with this bound in the working set
_PRIOR_SIDE = np.array([0, -1, 1])  # sides of PlanResult for a previous side -1 (unknown), 0 (right), 1 (left)


@dataclass(frozen=True)
class MIQPConfig:
    """Parameters of the passing-side MIQP."""

    nodes: int = 76
    """Number of coarse horizon nodes N [-] (node k is at time k * node_dt)."""
    node_dt: float = 0.15
    """Time between nodes [s]; the horizon spans (nodes - 1) * node_dt (11.25 s)."""
    w_dev: float = 1.0
    """Weight of the deviation (d_k - n_ref_k)^2 [1/m^2]."""
    w_smooth: float = 100.0
    """Weight of the smoothness (d_{k+1} - d_k)^2 [1/m^2]."""
    w_prev: float = 1.0
    """Weight of the consistency (d_k - d_prev_k)^2 with the previous plan [1/m^2]."""
    w_switch: float = 500.0
    """Hysteresis: cost of choosing a side different from the previous decision for
    the same opponent [-] (per opponent, (b - b_prev)^2 is linear in binary b)."""
    w_slack: float = 5e4
    """L1 penalty on the Big-M slack xi [1/m]."""
    safe_lat: float = 3.75
    """Lateral clearance from an opponent's centreline when passing it [m]."""
    safe_lon: float = 8.0
    """Longitudinal half-window [m]: an opponent's side constraint is active where
    the ego and its prediction are closer than this along the track. Coverage
    between nodes is handled separately (both end nodes of every node interval that
    touches the window are constrained, see the module docstring), so this is the
    car length plus a margin, not a node-spacing allowance; the effective window is
    at most one relative step (relative speed * node_dt) wider on each side."""
    closing_decel: float = 0.0
    """Deceleration [m/s^2] that sizes the braking-distance extension of the side-constraint
    window; 0 disables it (plain box window ``|gap| < safe_lon``). With a value ``a_b > 0``
    the window grows on the side the cars close in, by ``L = v_close^2 / (2 a_b)`` (the
    closing speed ``v_close`` from the ego's node speed and the opponent's speed), and the
    clearance there tapers elliptically: ``safe_lat * sqrt(1 - ((|gap| - safe_lon) / L)^2)``.
    This is the shape of the MPC's velocity-aware barrier (``a = a0 + v_close^2 / (2
    a_brake)``), so a plan that keeps it does not cross an opponent's lane inside its
    braking distance, which the barrier would forbid; the stack sets it to the barrier's
    ``a_brake``."""
    closing_stride: int = 3
    """In the braking-distance extension of the window (beyond ``safe_lon``), the
    clearance is imposed at every this-many-th node only, counted from the box window
    (the clearance decreases away from the box, so a kept node requires at least what
    the dropped nodes beyond it would): the extension spans up to ~20 nodes at high
    closing speed, and every pair adds two rows to the MIQP (solve time grows with
    them). The box window keeps every node; 1 keeps every node of the extension too."""
    track_margin: float = 1.2
    """Distance kept from each track edge [m]."""
    continuity: float = 0.3
    """Maximum |d_0 - ego_n| [m] (ego_n clipped into the corridor first, so the
    constraint can never be infeasible)."""
    cluster_gap: float = 10.0
    """Opponents closer than this to each other along the track [m], at a node where
    the ego overlaps either of them, share one side decision (no threading between
    them); linking is transitive."""
    solver: str = "daqp"
    """"daqp" (DAQP branch-and-bound) or "enumerate" (one QP per side pattern)."""

    def __post_init__(self) -> None:
        if self.nodes < 2:
            raise ValueError("nodes must be >= 2")
        if not self.node_dt > 0.0:
            raise ValueError("node_dt must be > 0")
        if not self.w_dev > 0.0:
            raise ValueError("w_dev must be > 0 (it makes the Hessian positive definite)")
        for name in ("w_smooth", "w_prev", "w_switch", "w_slack", "safe_lat",
                     "safe_lon", "closing_decel", "track_margin", "continuity", "cluster_gap"):
            if not getattr(self, name) >= 0.0:
                raise ValueError(f"{name} must be >= 0")
        if int(self.closing_stride) != self.closing_stride or self.closing_stride < 1:
            raise ValueError("closing_stride must be an integer >= 1")
        if self.solver not in ("daqp", "enumerate"):
            raise ValueError(f"unknown solver {self.solver!r} (use 'daqp' or 'enumerate')")


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


@dataclass
class _Problem:
    """Per-call data shared by the two solver routes (internal)."""

    lo: np.ndarray           # (N,) lower bounds on d (continuity included)
    hi: np.ndarray           # (N,) upper bounds on d
    f_d: np.ndarray          # (N,) linear cost on d (0.5 x'Hx + f'x convention)
    Rinv: np.ndarray         # (N, N) d = Rinv u
    RinvT: np.ndarray        # (N, N) its transpose (u-space cost f_u = RinvT f_d)
    pair_k: np.ndarray       # (P,) node of each active pair
    pair_c: np.ndarray       # (P,) cluster of each active pair
    pair_n: np.ndarray       # (P,) opponent offset of each active pair
    pair_w: np.ndarray       # (P,) lateral clearance required by each active pair [m]
    pair_r: np.ndarray       # (P,) relevant-opponent index of each active pair
    n_clusters: int
    f_b: np.ndarray          # (C,) linear hysteresis cost per cluster
    n_ref: np.ndarray
    d_prev: np.ndarray | None
    b_prev: np.ndarray       # (R,) previous side (1 left, 0 right, -1 unknown) per relevant opponent
    rel_cluster: np.ndarray  # (R,) cluster of each relevant opponent


class PassingSidePlanner:
    """Chooses the passing side of every relevant opponent and a lateral plan.

    Stateful only through the previous plan and decisions (consistency and
    hysteresis terms); :meth:`reset` forgets them. Never raises inside
    :meth:`plan` on numerical trouble: it returns a fallback plan with
    ``success=False`` and increments :attr:`n_failures`.
    """

    def __init__(self, config: MIQPConfig = MIQPConfig()):
        self.config = config
        N = config.nodes
        # Hessian blocks of d, built once: 2 * (w_dev I + w_smooth D'D [+ w_prev I]).
        D = np.diff(np.eye(N), axis=0)
        base = 2.0 * (config.w_dev * np.eye(N) + config.w_smooth * (D.T @ D))
        # Change of variables u = R d with H_d = R'R, so DAQP sees a diagonal
        # Hessian (its O(n) set-up path) and d = R^-1 u enters through fixed rows.
        self._fact = {}
        for key, H_d in ((False, base), (True, base + 2.0 * config.w_prev * np.eye(N))):
            R = np.linalg.cholesky(H_d).T                 # upper triangular, H_d = R'R
            Rinv = np.linalg.solve(R, np.eye(N))          # d = Rinv u
            self._fact[key] = (H_d, np.ascontiguousarray(Rinv), np.ascontiguousarray(Rinv.T))
        self._t = np.arange(N) * config.node_dt
        self._time_gradient = GridGradient(self._t)  # d/dt along the nodes (np.gradient, precomputed)
        self._node_idx = np.arange(N)
        # _thin_extension: whether a node at distance d (in nodes) from the box window is dropped
        stride = int(config.closing_stride)
        d = np.arange(8 * N + 1)
        self._thin_drop = (d > 1) & ((d - 1) % stride != 0)
        self._bnb_cache: dict = {}  # (C, P) -> Hessian, sense and index arrays of _solve_bnb
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

        lo, hi = self._corridor(n_min, n_max)
        # A sum is finite iff every term is (the magnitudes here cannot overflow).
        total = (s_nodes.sum() + n_ref.sum() + lo.sum() + hi.sum() + opp.sum() + opp_s.sum()
                 + float(ego_n) + float(progress))
        if not math.isfinite(total):
            return self._fallback(t0, s_nodes, n_ref, lo, hi, progress, opp, None,
                                  "non-finite input")

        try:
            clear = self._clearance(s_nodes, opp_s)
            active = clear > 0.0
            relevant = active.any(axis=1).nonzero()[0]
            if relevant.size == 0:
                d = n_ref.clip(lo, hi)
                self._remember(s_nodes, d, opp, np.zeros(M, dtype=int))
                return PlanResult(d=d, s=s_nodes.copy(), sides=np.zeros(M, dtype=int),
                                  objective=self._cost(d, n_ref, None, 0.0, 0.0),
                                  status="no_opponents", success=True,
                                  solve_time=time.perf_counter() - t0, n_binaries=0,
                                  opponent_slack=np.zeros(M))
            prob = self._build(s_nodes, n_ref, lo, hi, float(ego_n), float(progress), opp,
                               active, relevant, clear, opp_s)
        except Exception as exc:  # numerical trouble while building: never raise
            return self._fallback(t0, s_nodes, n_ref, lo, hi, progress, opp, None,
                                  f"build failed: {exc!r}")

        prior = self._prior_sides(relevant, prob.b_prev, M)
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
            return self._fallback(t0, s_nodes, n_ref, lo, hi, progress, opp, prior,
                                  "solver failed")
        d, b = sol
        d = d.clip(prob.lo, prob.hi)  # remove solver tolerance outside the hard bounds
        obj, xi = self._evaluate(prob, d, b)
        if not math.isfinite(obj):
            return self._fallback(t0, s_nodes, n_ref, lo, hi, progress, opp, prior,
                                  "non-finite objective")
        sides = np.zeros(M, dtype=int)
        sides[relevant] = np.where(b[prob.rel_cluster] > 0.5, 1, -1)
        opp_slack = np.zeros(M)
        np.maximum.at(opp_slack, relevant[prob.pair_r], xi)
        self._remember(s_nodes, d, opp, sides)
        return PlanResult(d=d, s=s_nodes.copy(), sides=sides, objective=obj,
                          status="optimal", success=True,
                          solve_time=time.perf_counter() - t0, n_binaries=prob.n_clusters,
                          max_slack=float(xi.max(initial=0.0)), slack_sum=float(xi.sum()),
                          opponent_slack=opp_slack)

    # ------------------------------------------------------------ components
    def _corridor(self, n_min: np.ndarray, n_max: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        m = self.config.track_margin
        lo = n_min + m
        hi = n_max - m
        narrow = lo > hi
        if narrow.any():
            mid = 0.5 * (n_min + n_max)
            lo = np.where(narrow, mid, lo)
            hi = np.where(narrow, mid, hi)
        return lo, hi

    def _closing_speed(self, gap: np.ndarray) -> np.ndarray:
        """``-np.gradient(gap, self._t, axis=1)``: the closing speed when the opponent is ahead."""
        out = self._time_gradient(gap)
        np.negative(out, out=out)
        return out

    def _clearance(self, s_nodes: np.ndarray, opp_s: np.ndarray) -> np.ndarray:
        """(M, N) lateral clearance [m] that node k must keep from opponent i; 0: no constraint.

        ``opp_s`` (M, N): the opponents' predicted arc lengths at the node times.

        A node gets the largest clearance required anywhere on its two adjacent node
        intervals: the plan and the gap are linear between nodes, so keeping that clearance
        at both end nodes keeps it on the whole interval.

        Rows are independent; opponents that cannot come within the (extended) window of
        the ego at any node or node interval get rows of zeros.

        (The arrays are small: the cost is the number of numpy calls, which is kept low;
        every value is computed with the same floating-point operations as the plain
        formulas in the comments.)
        """
        cfg = self.config
        N = cfg.nodes
        M = opp_s.shape[0]
        if M == 0:
            return np.zeros((0, N))
        L = cfg.safe_lon
        gap = opp_s - s_nodes[None, :]
        closing = cfg.closing_decel > 0.0
        two_decel = 2.0 * cfg.closing_decel
        # (Rows that cannot come within the window, |gap| >= L + the largest extension of the row
        # at every node and on every interval, come out as zeros; they are not filtered out first,
        # since the cost here is per numpy call, not per row.)
        if closing:
            dv = self._closing_speed(gap)
        a, b = gap[:, :-1], gap[:, 1:]
        # the point of each interval nearest to a zero gap (min(a, b) when both are positive,
        # max(a, b) when both are negative, else 0: the median of a, b and 0); nodes (first N
        # columns) and intervals (last N - 1) are evaluated together
        g_near = np.maximum(np.minimum(a, b), np.minimum(np.maximum(a, b), 0.0))
        g = np.concatenate([gap, g_near], axis=1)
        safe_lat = cfg.safe_lat
        over = np.abs(g) - L  # < 0 inside the box window |g| < L
        if closing:
            # window extension on the side the cars close in, per node: ext_a = max(dv, 0)^2 /
            # (2 closing_decel) ahead of the ego (g > 0), ext_b = max(-dv, 0)^2 / (2 closing_decel)
            # behind it, i.e. dv^2 / (2 closing_decel) where the sign of dv fits, else 0; per
            # interval the larger one of its two ends
            e_sq = dv ** 2 / two_decel
            pos_dv = dv > 0.0
            ext_a = np.where(pos_dv, e_sq, 0.0)
            ext_b = np.where(pos_dv, 0.0, e_sq)
            pos = g > 0.0
            ext = np.concatenate([np.where(pos[:, :N], ext_a, ext_b),
                                  np.where(pos[:, N:], np.maximum(ext_a[:, :-1], ext_a[:, 1:]),
                                           np.maximum(ext_b[:, :-1], ext_b[:, 1:]))], axis=1)
            # safe_lat inside the box, the elliptic taper safe_lat sqrt(1 - (over / ext)^2) in the
            # extension (0 <= over < ext; 1 - r^2 <= 1), 0 beyond
            with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
                r = over / ext
                cap = safe_lat * np.sqrt(np.maximum(1.0 - r * r, 0.0))
            out = np.where(over < 0.0, safe_lat, np.where(over < ext, cap, 0.0))
        else:
            out = np.where(over < 0.0, safe_lat, 0.0)
        w = out[:, :N]
        seg = out[:, N:]
        np.maximum(w[:, :-1], seg, out=w[:, :-1])
        np.maximum(w[:, 1:], seg, out=w[:, 1:])
        if cfg.closing_stride > 1 and closing:
            w = self._thin_extension(w, over[:, :N] < 0.0)
        return np.ascontiguousarray(w)

    def _thin_extension(self, w: np.ndarray, box: np.ndarray) -> np.ndarray:
        """Keep every ``closing_stride``-th constrained node outside the box window, counted outwards
        from it (the node next to the box is always kept). The clearance decreases away from the box,
        so each kept node requires at least what the dropped nodes beyond it would have."""
        outside = (w > 0.0) & ~box  # constrained nodes outside the box: the candidates
        if not outside.any():
            return w
        N = w.shape[1]
        k = self._node_idx
        big = 4 * N
        # distance (in nodes) to the nearest box node, from both sides
        last = np.maximum.accumulate(np.where(box, k, -big), axis=1)
        nxt = np.minimum.accumulate(np.where(box, k, 2 * big)[:, ::-1], axis=1)[:, ::-1]
        dist = np.minimum(k - last, nxt - k)
        # rows with candidates but no box node (window crossed between nodes): count from the
        # largest clearance
        empty = ~box.any(axis=1) & outside.any(axis=1)
        if empty.any():
            dist[empty] = np.abs(k[None, :] - np.argmax(w[empty], axis=1)[:, None])
        # dropped: candidates at a distance d > 1 with (d - 1) % stride != 0
        drop = outside & self._thin_drop[dist]
        if not drop.any():
            return w
        out = w.copy()
        out[drop] = 0.0
        return out

    def _clusters(self, pos: np.ndarray, act_rel: np.ndarray) -> tuple[int, np.ndarray]:
        """Connected components of the relation "must be passed on the same side".

        Two relevant opponents are linked when, at some node where the ego overlaps
        either of them (``act_rel``), they are closer than ``cluster_gap`` to each
        other along the track: the ego cannot thread between them there. (Opponents
        that only converge after the ego has passed them stay independent.)
        """
        R = pos.shape[0]
        if R == 1:
            return 1, np.zeros(1, dtype=int)
        close = np.abs(pos[:, None, :] - pos[None, :, :]) < self.config.cluster_gap
        either = act_rel[:, None, :] | act_rel[None, :, :]
        linked = (close & either).any(axis=2).tolist()
        labels = [-1] * R
        n = 0
        for i in range(R):
            if labels[i] >= 0:
                continue
            labels[i] = n
            stack = [i]
            while stack:
                j = stack.pop()
                for k in range(R):
                    if labels[k] < 0 and linked[j][k]:
                        labels[k] = n
                        stack.append(k)
            n += 1
        return n, np.asarray(labels, dtype=int)

    def _previous_plan_at(self, s_nodes: np.ndarray, progress: float) -> np.ndarray | None:
        if self._prev_d is None:
            return None
        return _interp_kernel(s_nodes + progress, self._prev_s, self._prev_d)  # np.interp

    def _previous_sides(self, s_nodes: np.ndarray, progress: float, opp_rel: np.ndarray,
                        relevant: np.ndarray) -> np.ndarray:
        """Previous side per relevant opponent: 1 left, 0 right, -1 unknown.

        Each current opponent inherits the side of the nearest opponent of the
        previous call (among those with a side), after propagating that one by the
        elapsed time estimated from ``progress`` and the ego speed, provided it lies
        within ``cluster_gap`` longitudinally and ``safe_lat`` laterally. Row order
        may therefore change between calls, and a respawned car (far away) does not
        inherit a stale decision.
        """
        cfg = self.config
        out = np.full(relevant.size, -1)
        if self._prev_sides is None or self._prev_opp is None:
            return out
        had_side = self._prev_sides != 0
        if not had_side.any():
            return out
        prev = self._prev_opp[had_side].tolist()
        prev_side = self._prev_sides[had_side].tolist()
        v_ego = float(s_nodes[1] - s_nodes[0]) / cfg.node_dt
        progress = float(progress)
        dt = progress / v_ego if v_ego > 0.1 and progress > 0.0 else 0.0
        s_pred = [row[0] + row[2] * dt - progress for row in prev]
        gap_scale = cfg.cluster_gap
        if not gap_scale > 0.0:  # no longitudinal match possible (x / 0 is inf or nan)
            return out
        lat_scale = max(cfg.safe_lat, 1e-9)
        # the same arithmetic as the array form, element by element (R, Mp <= a few)
        for r, (s_r, n_r) in enumerate(opp_rel[:, :2].tolist()):
            best, best_j = np.inf, -1
            for j, row in enumerate(prev):
                ds = abs(s_r - s_pred[j]) / gap_scale
                dn = abs(n_r - row[1]) / lat_scale
                if ds < 1.0 and dn < 1.0 and ds + dn < best:
                    best, best_j = ds + dn, j
            if best_j >= 0:
                out[r] = 1 if prev_side[best_j] > 0 else 0
        return out

    def _build(self, s_nodes, n_ref, lo, hi, ego_n, progress, opp, active, relevant, clear, opp_s) -> _Problem:
        cfg = self.config
        opp_rel = opp[relevant]
        act_rel = active[relevant]
        n_clusters, labels = self._clusters(opp_s[relevant], act_rel)

        lo = lo.copy()
        hi = hi.copy()
        lo_0, hi_0 = float(lo[0]), float(hi[0])
        e = min(max(ego_n, lo_0), hi_0)
        lo[0] = max(lo_0, e - cfg.continuity)
        hi[0] = min(hi_0, e + cfg.continuity)

        d_prev = self._previous_plan_at(s_nodes, progress)
        _, Rinv, RinvT = self._fact[d_prev is not None]
        if d_prev is None:
            f_d = -2.0 * cfg.w_dev * n_ref
        else:
            f_d = -2.0 * (cfg.w_dev * n_ref + cfg.w_prev * d_prev)

        b_prev = self._previous_sides(s_nodes, progress, opp_rel, relevant)
        known = b_prev >= 0
        # w (b - bp)^2 = w (1 - 2 bp) b + w bp for binary b and bp (constant dropped), summed per cluster.
        f_b = np.bincount(labels[known], weights=cfg.w_switch * (1.0 - 2.0 * b_prev[known]), minlength=n_clusters)

        rows, ks = act_rel.nonzero()
        return _Problem(lo=lo, hi=hi, f_d=f_d, Rinv=Rinv, RinvT=RinvT, pair_k=ks,
                        pair_c=labels[rows], pair_n=opp_rel[rows, 1],
                        pair_w=clear[relevant[rows], ks], pair_r=rows, n_clusters=n_clusters,
                        f_b=f_b, n_ref=n_ref, d_prev=d_prev, b_prev=b_prev, rel_cluster=labels)

    # ------------------------------------------------------------- solvers
    def _solve_bnb(self, prob: _Problem) -> tuple[np.ndarray, np.ndarray] | None:
        """DAQP branch-and-bound over x = [b (C), xi (P), u (N)], d = Rinv u.

        Simple bounds: b in [0, 1] (binary), xi >= 0. General rows: the corridor
        lo <= Rinv u <= hi, then the two Big-M rows of every active pair.
        """
        if daqp is None:
            return None
        cfg = self.config
        C, N, P = prob.n_clusters, prob.lo.size, prob.pair_k.size
        nv = C + P + N
        sl = prob.pair_w
        lo_k, hi_k = prob.lo[prob.pair_k], prob.hi[prob.pair_k]
        Ma = np.maximum(0.0, hi_k - prob.pair_n + sl)
        Mb = np.maximum(0.0, prob.pair_n + sl - lo_k)

        key = (C, P)
        cached = self._bnb_cache.get(key)
        if cached is None:
            Hv = np.empty(nv)
            Hv[:C] = _Q_BIN
            Hv[C:C + P] = _Q_SLACK
            Hv[C + P:] = 1.0
            sense = np.zeros(C + P + N + 2 * P, dtype=np.int32)
            sense[:C] = _SENSE_BINARY
            # Slacks start at their bound xi = 0: without this warm start the active set
            # needs one iteration per pair just to add the xi >= 0 bounds.
            sense[C:C + P] = _SENSE_ACTIVE_LOWER
            r2 = np.arange(2 * P)
            slack_col = C + np.concatenate([np.arange(P), np.arange(P)])
            slack_val = np.concatenate([-np.ones(P), np.ones(P)])
            # the constant parts of the bounds (the others are written per call)
            bupper = np.empty(C + P + N + 2 * P)
            bupper[:C] = 1.0
            bupper[C:C + P] = _INF
            bupper[C + 2 * P + N:] = _INF
            blower = np.empty(C + P + N + 2 * P)
            blower[:C + P] = 0.0
            blower[C + P + N:C + 2 * P + N] = -_INF
            cached = (np.diag(Hv), sense, N + r2, slack_col, slack_val, bupper, blower)
            if len(self._bnb_cache) > 64:
                self._bnb_cache.clear()
            self._bnb_cache[key] = cached
        H, sense, rows2, slack_col, slack_val, bupper, blower = cached
        f = np.empty(nv)
        f[:C] = prob.f_b - 0.5 * _Q_BIN
        f[C:C + P] = cfg.w_slack
        f[C + P:] = prob.RinvT @ prob.f_d
        A = np.zeros((N + 2 * P, nv))
        A[:N, C + P:] = prob.Rinv
        pk2 = np.concatenate([prob.pair_k, prob.pair_k])
        A[N:, C + P:] = prob.Rinv[pk2]
        A[rows2, np.concatenate([prob.pair_c, prob.pair_c])] = -np.concatenate([Ma, Mb])
        A[rows2, slack_col] = slack_val
        bupper = bupper.copy()
        bupper[C + P:C + P + N] = prob.hi
        bupper[C + P + N:C + 2 * P + N] = prob.pair_n - sl
        blower = blower.copy()
        blower[C + P:C + P + N] = prob.lo
        blower[C + 2 * P + N:] = prob.pair_n + sl - Mb
        x, _, flag, _ = daqp.solve(H, f, A, bupper, blower, sense.copy(), presolve=0)
        if flag not in _DAQP_OK:
            logger.debug("DAQP branch-and-bound exit flag %d", flag)
            return None
        x = np.asarray(x)
        return prob.Rinv @ x[C + P:], x[:C].round()

    def _solve_enumerate(self, prob: _Problem) -> tuple[np.ndarray, np.ndarray] | None:
        """One QP over x = [xi (P), u (N)] per side pattern (2^C of them)."""
        if daqp is None:
            return None
        cfg = self.config
        C, N, P = prob.n_clusters, prob.lo.size, prob.pair_k.size
        nv = P + N
        sl = prob.pair_w
        H = np.diag(np.concatenate([np.full(P, _Q_SLACK), np.ones(N)]))
        f = np.concatenate([np.full(P, cfg.w_slack), prob.RinvT @ prob.f_d])
        r = np.arange(P)
        A = np.zeros((N + P, nv))
        A[:N, P:] = prob.Rinv
        A[N:, P:] = prob.Rinv[prob.pair_k]
        bup = np.concatenate([np.full(P, _INF), prob.hi, np.empty(P)])
        blo = np.concatenate([np.zeros(P), prob.lo, np.empty(P)])
        sense = np.zeros(P + N + P, dtype=np.int32)
        sense[:P] = _SENSE_ACTIVE_LOWER  # warm start: slacks at zero
        best = None
        best_cost = np.inf
        for pattern in range(1 << C):
            b = np.array([(pattern >> c) & 1 for c in range(C)], dtype=float)
            left = b[prob.pair_c] > 0.5
            # left: d_k + xi >= n + sl;  right: d_k - xi <= n - sl
            A[N + r, r] = np.where(left, 1.0, -1.0)
            bup[P + N:] = np.where(left, _INF, prob.pair_n - sl)
            blo[P + N:] = np.where(left, prob.pair_n + sl, -_INF)
            x, fval, flag, _ = daqp.solve(H, f, A, bup, blo, sense)
            if flag not in _DAQP_OK:
                logger.debug("DAQP exit flag %d for side pattern %d", flag, pattern)
                return None
            cost = fval + float(prob.f_b @ b)
            if cost < best_cost:
                best_cost = cost
                best = (prob.Rinv @ np.asarray(x)[P:], b)
        return best

    # ----------------------------------------------------------- evaluation
    def _cost(self, d, n_ref, d_prev, switch_cost, slack_cost) -> float:
        cfg = self.config
        dd = d[1:] - d[:-1]  # np.diff(d)
        val = cfg.w_dev * float(((d - n_ref) ** 2).sum()) + cfg.w_smooth * float(dd @ dd)
        if d_prev is not None:
            val += cfg.w_prev * float(((d - d_prev) ** 2).sum())
        return val + switch_cost + slack_cost

    def _evaluate(self, prob: _Problem, d: np.ndarray, b: np.ndarray) -> tuple[float, np.ndarray]:
        """Exact cost of ``(d, b)`` with the minimal slack, and that slack per pair."""
        cfg = self.config
        left = b[prob.pair_c] > 0.5
        dk = d[prob.pair_k]
        xi = np.where(left, prob.pair_n + prob.pair_w - dk, dk - (prob.pair_n - prob.pair_w))
        xi = np.where(xi > _SLACK_TOL, xi, 0.0)
        known = prob.b_prev >= 0
        bi = b[prob.rel_cluster][known]
        switch = cfg.w_switch * float(((bi - prob.b_prev[known]) ** 2).sum())
        return self._cost(d, prob.n_ref, prob.d_prev, switch, cfg.w_slack * float(xi.sum())), xi

    # ------------------------------------------------------------- helpers
    def _prior_sides(self, relevant: np.ndarray, b_prev: np.ndarray, M: int) -> np.ndarray:
        sides = np.zeros(M, dtype=int)
        sides[relevant] = _PRIOR_SIDE[b_prev + 1]  # b_prev 1 -> 1 (left), 0 -> -1 (right), -1 -> 0 (unknown)
        return sides

    def _remember(self, s_nodes, d, opp, sides) -> None:
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
