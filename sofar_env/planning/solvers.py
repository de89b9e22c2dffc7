"""The two exact solver routes of the passing-side MIQP, both on DAQP.

``solve_branch_and_bound`` uses DAQP's built-in branch-and-bound: the binaries are
simple bounds ``0 <= b <= 1`` flagged binary (``sense`` 16); the general rows are the
corridor and the two Big-M rows of every active pair::

    d_k <= n_i - w_ik + Ma_ik * b + xi_ik
    d_k >= n_i + w_ik - Mb_ik * (1 - b) - xi_ik

with the tightest valid constants ``Ma_ik = max(0, hi_k - n_i + w_ik)`` and ``Mb_ik =
max(0, n_i + w_ik - lo_k)`` (each is the smallest value that makes the relaxed row
redundant inside the corridor ``[lo_k, hi_k]``). They are at most the track width plus
the clearance, instead of a fixed large constant such as 2000, which keeps the
relaxations tight and the problem well conditioned. ``solve_enumeration`` solves one
QP per side pattern (``2^C``, C <= 4 in practice) and keeps the best. A cluster whose side is locked
(``SideProblem.b_fixed``) has its binary's bounds pinned in the first route and only its side
enumerated in the second. Both return
``(d, b)`` or None when DAQP fails.

Numerics. The solvers work in ``u = R d`` (``H_d = R'R``, see
:func:`sofar_env.planning.problem.cost_factors`): DAQP then sees a *diagonal*
Hessian, for which its set-up is O(n) instead of a dense factorisation; ``d = R^-1
u`` enters through fixed rows. DAQP needs a strictly positive-definite Hessian, so
binaries get curvature ``_Q_BIN`` (cancelled exactly at 0/1 by a linear term, so the
relaxation stays a valid lower bound) and slacks a small curvature ``_Q_SLACK`` (a
perturbation of order 1e-7 of the objective when slack is used, none otherwise).
Slacks start in DAQP's working set at their bound (warm start), which saves one
active-set iteration per pair.

Incumbent. Before the branch-and-bound starts, :func:`_incumbent_bound` evaluates a few feasible points:
for each free side pattern, the previous plan at the new nodes (or the reference), clipped to the corridor and
moved at each active pair's node to the pattern's side of the clearance, with the slacks that remain. The
best objective, plus a margin of 1e-6, goes to DAQP as ``fval_bound``: a node whose relaxation is above it
is dropped, and since DAQP's solver is a dual active-set method, whose objective only grows during a node's
solve, it is dropped as soon as its objective passes the bound. The nodes on the way to the optimum are
below the bound and are solved exactly as without it (tests/planning/test_solvers.py compares the returned
values bit for bit). If the bound is below the optimum (the margin missed, or the point was the optimum
itself), DAQP reports infeasible and the call is repeated without it. On the calls of a closed loop of the
env this cuts the branch and bound's time by about 1.25x (rho 0.5) to 1.35x (rho 0.3).

Compiled route. With the pinned DAQP (:mod:`~sofar_env.planning.daqp_c`), the data, the incumbent, DAQP's branch
and bound and its repetition without the bound are one compiled call (:func:`_bnb_solve`, DAQP's C API called from
the kernel); otherwise (:data:`NATIVE` False) the same steps run from Python around ``daqp.solve``. Both give the
same values to the bit (tests/planning/test_daqp_c.py). The products with ``R^-1`` stay numpy calls on either
route: their bits are those of numpy's BLAS.

Per-call cost. The diagonal Hessian, the constraint types, the index arrays and the
constant parts of the bounds of the branch-and-bound depend only on ``(C, P)`` and
are kept in a cache owned by the caller (the planner).
"""

from __future__ import annotations

import logging

import numpy as np

from .._jit import kernel, py_max, py_min
from . import daqp_c
from .problem import SideProblem

try:  # DAQP is a hard dependency, but the planner must never raise because of it.
    import daqp
except ImportError:  # pragma: no cover - exercised only in broken installs
    daqp = None

__all__ = ["solve_branch_and_bound", "solve_enumeration"]

logger = logging.getLogger(__name__)

_INF = 1e30          # DAQP's notion of an infinite bound
_Q_BIN = 1.0         # curvature added to each binary; cancelled at 0/1 by a linear term
_Q_SLACK = 1e-2      # curvature added to each slack [1/m^2] (DAQP needs H > 0)
_DAQP_OK = (1, 2)    # DAQP exit flags that mean "optimal" (2: optimal with soft constraints)
_DAQP_INFEASIBLE = -1  # DAQP's exit flag when no node beats fval_bound (or the problem is infeasible)
DAQP_CYCLE_TOL = 10  # DAQP's default cycle_tol (MIQPConfig.daqp_cycle_tol)
_BOUND_MARGIN = 1e-6  # relative (and absolute) margin on the incumbent's objective [-]
_BOUND_MAX_CLUSTERS = 8  # the incumbent tries every side pattern: up to 2^8 of them, else no incumbent
_SENSE_BINARY = 16
_SENSE_ACTIVE_LOWER = 3   # DAQP: ACTIVE (1) | LOWER (2): start with this bound in the working set
_NO_FIXED = np.zeros(0, dtype=np.int64)
_WORKSPACE = "daqp workspace"  # key of the compiled route's DAQP records and buffers in the caller's cache

NATIVE = daqp_c.AVAILABLE
"""Whether :func:`solve_branch_and_bound` takes the compiled route (:func:`_bnb_solve`, DAQP's C API from a kernel)
instead of building the data and calling ``daqp.solve`` from Python; the two give the same values to the bit."""


def solve_branch_and_bound(prob: SideProblem, w_slack: float, cache: dict,
                           cycle_tol: int = DAQP_CYCLE_TOL) -> tuple[np.ndarray, np.ndarray] | None:
    """DAQP branch-and-bound over x = [b (C), xi (P), u (N)], d = Rinv u.

    Simple bounds: b in [0, 1] (binary), xi >= 0. General rows: the corridor
    lo <= Rinv u <= hi, then the two Big-M rows of every active pair. ``cycle_tol``: DAQP's setting
    (``MIQPConfig.daqp_cycle_tol``). None when DAQP exits with any flag but optimal.
    """
    if daqp is None:
        return None
    C, N, P = prob.n_clusters, prob.lo.size, prob.pair_k.size
    nv = C + P + N
    key = (C, P)
    cached = cache.get(key)
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
        cached = (np.diag(Hv), sense)
        if len(cache) > 64:
            cache.clear()
        cache[key] = cached
    H, sense = cached
    b_fixed = prob.b_fixed if prob.b_fixed is not None else _NO_FIXED
    if NATIVE:
        work = cache.get(_WORKSPACE)
        if work is None:
            work = cache[_WORKSPACE] = daqp_c.Workspace()
        work.records[1][0]["cycle_tol"] = cycle_tol
        start = prob.d_prev if prob.d_prev is not None else prob.n_ref
        lateral = (prob.f_d, start, prob.w_diag is not None, prob.w_diag or 0.0, float(prob.w_smooth))
        flag, x = _bnb_solve(C, prob.Rinv, prob.RinvT @ prob.f_d, prob.f_b, float(w_slack), (prob.lo, prob.hi),
                             (prob.pair_k, prob.pair_c, prob.pair_n, prob.pair_w), b_fixed, lateral, H, sense,
                             work.records, work.reserve(nv, sense.shape[0]))
        if flag not in _DAQP_OK:
            logger.debug("DAQP branch-and-bound exit flag %d", flag)
            return None
        return prob.Rinv @ x[C + P:], x[:C].round()
    f, A, bupper, blower = _bnb_data(C, prob.Rinv, prob.RinvT @ prob.f_d, prob.f_b, float(w_slack), prob.lo, prob.hi,
                                     prob.pair_k, prob.pair_c, prob.pair_n, prob.pair_w, b_fixed)
    bound = _INF
    if prob.w_diag is not None:
        start = prob.d_prev if prob.d_prev is not None else prob.n_ref
        bound = _incumbent_bound(C, f, prob.f_d, prob.w_diag, prob.w_smooth, prob.lo, prob.hi, start, prob.pair_k,
                                 prob.pair_c, prob.pair_n, prob.pair_w, b_fixed)
    x, _, flag, _ = daqp.solve(H, f, A, bupper, blower, sense.copy(), presolve=0, fval_bound=bound,
                               cycle_tol=cycle_tol)
    if flag == _DAQP_INFEASIBLE and bound < _INF:
        # the incumbent pruned every node (it was optimal to within the margin): once more without it
        x, _, flag, _ = daqp.solve(H, f, A, bupper, blower, sense.copy(), presolve=0, cycle_tol=cycle_tol)
    if flag not in _DAQP_OK:
        logger.debug("DAQP branch-and-bound exit flag %d", flag)
        return None
    x = np.asarray(x)
    return prob.Rinv @ x[C + P:], x[:C].round()


@kernel
def _bnb_solve(C, Rinv, f_u, f_b, w_slack, corridor, pairs, b_fixed, lateral, H, sense, records, buffers):
    """The Python route of :func:`solve_branch_and_bound` from its data to DAQP's solution in one compiled call:
    :func:`_bnb_data`, the incumbent (:func:`_incumbent_bound`, when ``lateral[2]``), DAQP's branch and bound
    (:func:`.daqp_c.quadprog`, ``presolve=0``) and, when the bound pruned every node, the search once more
    without it. ``corridor = (lo, hi)``, ``pairs = (pair_k, pair_c, pair_n, pair_w)``, ``lateral = (f_d, start,
    use_bound, w_diag, w_smooth)``; ``records``, ``buffers`` of a :class:`.daqp_c.Workspace`. Returns DAQP's exit
    flag and a copy of x = [b (C), xi (P), u (N)]."""
    lo, hi = corridor
    pair_k, pair_c, pair_n, pair_w = pairs
    f_d, start, use_bound, w_diag, w_smooth = lateral
    f, A, bupper, blower = _bnb_data(C, Rinv, f_u, f_b, w_slack, lo, hi, pair_k, pair_c, pair_n, pair_w, b_fixed)
    bound = _INF
    if use_bound:
        bound = _incumbent_bound(C, f, f_d, w_diag, w_smooth, lo, hi, start, pair_k, pair_c, pair_n, pair_w, b_fixed)
    flag, _ = daqp_c.quadprog(H, f, A, bupper, blower, sense, bound, 0, records, buffers)
    if flag == _DAQP_INFEASIBLE and bound < _INF:
        flag, _ = daqp_c.quadprog(H, f, A, bupper, blower, sense, _INF, 0, records, buffers)
    return flag, buffers[0][:f.shape[0]].copy()


@kernel
def _bnb_data(C, Rinv, f_u, f_b, w_slack, lo, hi, pair_k, pair_c, pair_n, pair_w, b_fixed):
    """Cost vector, constraint matrix and bounds of :func:`solve_branch_and_bound` over x = [b (C), xi (P),
    u (N)] (``f_u = R^-T f_d`` is given): ``f = (f_b - Q_BIN / 2, w_slack, f_u)``; simple bounds b in [0, 1]
    (pinned where ``b_fixed >= 0``; ``b_fixed`` empty: none pinned) and xi >= 0; general rows: the corridor ``lo <= Rinv u <= hi``, then per
    pair r (node k, cluster c) ``Rinv_k u - Ma b_c - xi_r <= n - w`` and ``Rinv_k u - Mb b_c + xi_r >= n + w -
    Mb`` with ``Ma = max(0, hi_k - n + w)`` and ``Mb = max(0, n + w - lo_k)`` (module docstring). Each value
    with the operations of the numpy form it replaced, in the same order."""
    N = lo.shape[0]
    P = pair_k.shape[0]
    nv = C + P + N
    f = np.empty(nv)
    A = np.zeros((N + 2 * P, nv))
    bupper = np.empty(C + P + N + 2 * P)
    blower = np.empty(C + P + N + 2 * P)
    for c in range(C):
        f[c] = f_b[c] - 0.5 * _Q_BIN
        if b_fixed.shape[0] > 0 and b_fixed[c] >= 0:
            bupper[c] = blower[c] = float(b_fixed[c])
        else:
            bupper[c], blower[c] = 1.0, 0.0
    for r in range(P):
        f[C + r] = w_slack
        bupper[C + r], blower[C + r] = _INF, 0.0
    for k in range(N):
        f[C + P + k] = f_u[k]
        bupper[C + P + k], blower[C + P + k] = hi[k], lo[k]
        for j in range(N):
            A[k, C + P + j] = Rinv[k, j]
    for r in range(P):
        k = pair_k[r]
        sl, n = pair_w[r], pair_n[r]
        x = hi[k] - n + sl
        ma = 0.0 if 0.0 >= x else x
        x = n + sl - lo[k]
        mb = 0.0 if 0.0 >= x else x
        for j in range(N):
            A[N + r, C + P + j] = Rinv[k, j]
            A[N + P + r, C + P + j] = Rinv[k, j]
        A[N + r, pair_c[r]] = -ma
        A[N + P + r, pair_c[r]] = -mb
        A[N + r, C + r] = -1.0
        A[N + P + r, C + r] = 1.0
        bupper[C + P + N + r], blower[C + P + N + r] = n - sl, -_INF
        bupper[C + 2 * P + N + r], blower[C + 2 * P + N + r] = _INF, n + sl - mb
    return f, A, bupper, blower


def solve_enumeration(prob: SideProblem, w_slack: float,
                      cycle_tol: int = DAQP_CYCLE_TOL) -> tuple[np.ndarray, np.ndarray] | None:
    """One QP over x = [xi (P), u (N)] per side pattern (2^C of them); ``cycle_tol`` as in
    :func:`solve_branch_and_bound`. None when any pattern's QP exits with a flag but optimal."""
    if daqp is None:
        return None
    C, N, P = prob.n_clusters, prob.lo.size, prob.pair_k.size
    nv = P + N
    sl = prob.pair_w
    H = np.diag(np.concatenate([np.full(P, _Q_SLACK), np.ones(N)]))
    f = np.concatenate([np.full(P, w_slack), prob.RinvT @ prob.f_d])
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
        if prob.b_fixed is not None and np.any((prob.b_fixed >= 0) & (b != prob.b_fixed)):
            continue  # a locked side
        left = b[prob.pair_c] > 0.5
        # left: d_k + xi >= n + sl;  right: d_k - xi <= n - sl
        A[N + r, r] = np.where(left, 1.0, -1.0)
        bup[P + N:] = np.where(left, _INF, prob.pair_n - sl)
        blo[P + N:] = np.where(left, prob.pair_n + sl, -_INF)
        x, fval, flag, _ = daqp.solve(H, f, A, bup, blo, sense, cycle_tol=cycle_tol)
        if flag not in _DAQP_OK:
            logger.debug("DAQP exit flag %d for side pattern %d", flag, pattern)
            return None
        cost = fval + float(prob.f_b @ b)
        if cost < best_cost:
            best_cost = cost
            best = (prob.Rinv @ np.asarray(x)[P:], b)
    return best


@kernel
def _incumbent_bound(C, f, f_d, w_diag, w_smooth, lo, hi, start, pair_k, pair_c, pair_n, pair_w, b_fixed):
    """An upper bound on the optimal objective of :func:`solve_branch_and_bound`, for DAQP's ``fval_bound``:
    the objective ``0.5 x'Hx + f'x`` of the best of a few feasible points, plus a margin of ``_BOUND_MARGIN``
    (relative and absolute). For every free side pattern ``b``: ``d = clip(start, lo, hi)`` (``start``: the
    previous plan at the new nodes, or the reference), moved at each active pair's node to the pattern's side
    of the clearance (within the corridor), with the minimal slacks of the Big-M rows. The lateral part is
    evaluated in d (``0.5 u'u + f_u'u = w_diag |d|^2 + w_smooth |diff d|^2 + f_d'd``, ``H_d = 2 (w_diag I +
    w_smooth D'D)``). DAQP drops every node whose relaxation is above the bound; the node that holds the
    optimum is reached as before. ``_INF`` (no bound) when no point is finite, or with more than
    ``_BOUND_MAX_CLUSTERS`` side decisions (their patterns would cost more than the search they prune)."""
    if C > _BOUND_MAX_CLUSTERS:
        return _INF
    N = lo.shape[0]
    P = pair_k.shape[0]
    d0 = np.empty(N)
    for k in range(N):
        d0[k] = py_min(py_max(start[k], lo[k]), hi[k])  # clip
    d = np.empty(N)
    best = _INF
    for pattern in range(1 << C):
        if _locked_out(pattern, C, b_fixed):
            continue
        val = 0.0
        for c in range(C):
            b = (pattern >> c) & 1
            val += 0.5 * _Q_BIN * b * b + f[c] * b
        d[:] = d0
        for r in range(P):
            k = pair_k[r]
            if (pattern >> pair_c[r]) & 1:
                d[k] = py_min(py_max(d[k], pair_n[r] + pair_w[r]), hi[k])
            else:
                d[k] = py_max(py_min(d[k], pair_n[r] - pair_w[r]), lo[k])
        for r in range(P):
            # inside the corridor the Big-M row of the other side holds by itself: the pattern's side decides
            k = pair_k[r]
            if (pattern >> pair_c[r]) & 1:
                xi = py_max(0.0, pair_n[r] + pair_w[r] - d[k])
            else:
                xi = py_max(0.0, d[k] - (pair_n[r] - pair_w[r]))
            val += 0.5 * _Q_SLACK * xi * xi + f[C + r] * xi
        for k in range(N):
            val += w_diag * d[k] * d[k] + f_d[k] * d[k]
            if k > 0:
                dd = d[k] - d[k - 1]
                val += w_smooth * dd * dd
        best = py_min(best, val)
    if not (abs(best) < _INF):
        return _INF
    return best + _BOUND_MARGIN * (abs(best) + 1.0)


@kernel
def _locked_out(pattern, C, b_fixed):
    """Whether the side pattern (bit c: cluster c passed on the left) contradicts a locked side of ``b_fixed``
    (empty: none locked)."""
    if b_fixed.shape[0] == 0:
        return False
    for c in range(C):
        if b_fixed[c] >= 0 and b_fixed[c] != (pattern >> c) & 1:
            return True
    return False
