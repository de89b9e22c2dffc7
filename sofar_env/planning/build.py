"""The passing-side problem of one :meth:`~sofar_env.planning.miqp.PassingSidePlanner.plan` call, built in one
compiled call (:mod:`sofar_env._jit`).

:func:`build_problem` goes from the planner's inputs to the data of :class:`~.problem.SideProblem`: the corridor
and the finiteness test (:func:`~.miqp._corridor`), the clearance table (:func:`~.clearance._clearance_table`),
the relevant opponents, the cars alongside and their side locks, the side clusters
(:func:`~.clearance._side_clusters`), the continuity bounds of node 0, the previous plan at the new nodes
(``np.interp``'s arithmetic, :func:`sofar_env._interp.interp_at`), the linear cost, the previous sides
(:func:`~.hysteresis._match`), the hysteresis cost per cluster and the active pairs. Each value with the
operations of the numpy form it replaced, in the same order (tests/planning/test_build.py compares the two bit
for bit); matrix products (BLAS) are left to the caller (why, and the measurements:
docs/decisions/compiled-planner.md).

Inputs bundled per concept: ``nodes = (s_nodes, n_ref, n_min, n_max)``; ``ego = (ego_n, progress)``; ``previous
= (has_plan, prev_s, prev_d, has_sides, prev_opp, prev_sides)`` (the planner's memory; the flags say whether the
plan and the sides exist); ``weights = (track_margin, continuity, w_dev, w_prev, w_switch, alongside_gap,
cluster_gap, safe_lat, node_dt)``; ``window`` the arguments of the clearance table after ``opp_s`` (the gradient
coefficients and ``safe_lon, safe_lat, closing_decel, ellipse, stride``).
"""

from __future__ import annotations

import numpy as np

from .._interp import interp_located, locate
from .._jit import kernel, maximum, py_max, py_min
from .clearance import _clearance_table, _side_clusters
from .hysteresis import _match
from .problem import _slack_and_switch

__all__ = ["build_problem", "finish_plan", "UNBOUNDED", "NO_OPPONENTS", "PROBLEM"]

UNBOUNDED = 0
"""Some input is not finite or above 1e300 in magnitude: the caller tests the sum of the inputs (nothing else
was computed)."""
NO_OPPONENTS = 1
"""No opponent has an active node: only the corridor was computed."""
PROBLEM = 2
"""A problem was built."""

_NONE_INT = np.zeros(0, dtype=np.int64)
_NOT_APART = np.zeros((0, 0), dtype=np.bool_)


@kernel
def _corridor(n_min, n_max, margin, s_nodes, n_ref, opp, opp_s, ego_n, progress):
    """Bounds on d, the edges ``n_min``, ``n_max`` [m] moved in by ``margin`` (``track_margin``), their centre
    ``0.5 (n_min + n_max)`` where they cross; and whether every input of the plan (these, ``s_nodes``,
    ``n_ref``, the opponents, ``ego_n``, ``progress``) is finite with a magnitude below 1e300, so that
    their sum is finite (else the caller takes the sum)."""
    N = n_min.shape[0]
    lo = np.empty(N)
    hi = np.empty(N)
    big = 1e300
    bounded = abs(ego_n) <= big and abs(progress) <= big
    for k in range(N):
        a = n_min[k] + margin
        b = n_max[k] - margin
        if a > b:
            a = b = 0.5 * (n_min[k] + n_max[k])
        lo[k], hi[k] = a, b
        bounded = (bounded and abs(a) <= big and abs(b) <= big and abs(s_nodes[k]) <= big
                   and abs(n_ref[k]) <= big)
    for i in range(opp.shape[0]):
        for c in range(opp.shape[1]):
            bounded = bounded and abs(opp[i, c]) <= big
        for c in range(opp_s.shape[1]):
            bounded = bounded and abs(opp_s[i, c]) <= big
    return lo, hi, bounded


@kernel
def build_problem(nodes, opp, opp_s, ego, previous, weights, window, checked):
    """The problem data of one plan call (module docstring). ``checked``: the inputs are known to have a finite
    sum (skip the finiteness test). Returns ``(status, lo, hi, relevant, problem)`` with ``status`` one of
    :data:`UNBOUNDED`, :data:`NO_OPPONENTS`, :data:`PROBLEM`; ``lo, hi`` the corridor, ``relevant`` the
    relevant opponents' rows; ``problem = (n_clusters, labels, lo, hi, d_prev, f_d, b_prev, f_b, b_fixed,
    pair_k, pair_c, pair_n, pair_w, pair_r)``, its ``lo, hi`` with node 0's continuity bounds, ``d_prev``
    empty without a previous plan and ``b_fixed`` empty without a car alongside (arrays of the other statuses
    are empty)."""
    s_nodes, n_ref, n_min, n_max = nodes
    ego_n, progress = ego
    has_plan, prev_s, prev_d, has_sides, prev_opp, prev_sides = previous
    track_margin, continuity, w_dev, w_prev, w_switch, alongside_gap, cluster_gap, safe_lat, node_dt = weights
    uniform, two_dx, dx0, dxn, ga, gb, gc, safe_lon, safe_lat_w, closing_decel, ellipse, stride = window
    N = s_nodes.shape[0]
    M = opp.shape[0]
    empty_f = np.zeros(0)
    empty_i = np.zeros(0, dtype=np.int64)
    nothing = (0, empty_i, empty_f, empty_f, empty_f, empty_f, empty_i, empty_f, empty_i, empty_i, empty_i, empty_f,
               empty_f, empty_i)
    lo, hi, bounded = _corridor(n_min, n_max, track_margin, s_nodes, n_ref, opp, opp_s, ego_n, progress)
    if not (bounded or checked):
        return UNBOUNDED, lo, hi, empty_i, nothing
    clear = _clearance_table(s_nodes, opp_s, uniform, two_dx, dx0, dxn, ga, gb, gc, safe_lon, safe_lat_w,
                             closing_decel, ellipse, stride)
    R = 0
    for i in range(M):
        for k in range(N):
            if clear[i, k] > 0.0:
                R += 1
                break
    relevant = np.empty(R, dtype=np.int64)
    r = 0
    for i in range(M):
        for k in range(N):
            if clear[i, k] > 0.0:
                relevant[r] = i
                r += 1
                break
    if R == 0:
        return NO_OPPONENTS, lo, hi, relevant, nothing

    # clusters; two cars alongside the ego, one on each side, are never linked
    pos = np.empty((R, N))
    act = np.empty((R, N), dtype=np.bool_)
    for r in range(R):
        for k in range(N):
            pos[r, k] = opp_s[relevant[r], k]
            act[r, k] = clear[relevant[r], k] > 0.0
    lock = alongside_gap > 0.0
    along = np.zeros(R, dtype=np.bool_)
    apart = _NOT_APART
    if lock:
        apart = np.empty((R, R), dtype=np.bool_)
        for r in range(R):
            along[r] = abs(opp[relevant[r], 0]) < alongside_gap
        for r in range(R):
            for q in range(R):
                apart[r, q] = (along[r] and along[q]
                               and (opp[relevant[r], 1] > ego_n) != (opp[relevant[q], 1] > ego_n))
    if R == 1:
        C = 1
        labels = np.zeros(1, dtype=np.int64)
    else:
        C, labels = _side_clusters(pos, act, cluster_gap, apart)

    # continuity at node 0 (Python's min and max of floats)
    p_lo = lo.copy()
    p_hi = hi.copy()
    lo_0, hi_0 = lo[0], hi[0]
    e = py_min(py_max(ego_n, lo_0), hi_0)
    p_lo[0] = py_max(lo_0, e - continuity)
    p_hi[0] = py_min(hi_0, e + continuity)

    # the previous plan at the new nodes, and the linear cost on d
    f_d = np.empty(N)
    d_prev = empty_f
    if has_plan:
        d_prev = np.empty(N)
        j = -1
        for k in range(N):
            x = s_nodes[k] + progress
            j = locate(x, prev_s, j)
            d_prev[k] = interp_located(j, x, prev_s, prev_d)
        for k in range(N):
            f_d[k] = -2.0 * (w_dev * n_ref[k] + w_prev * d_prev[k])
    else:
        scale = -2.0 * w_dev
        for k in range(N):
            f_d[k] = scale * n_ref[k]

    # previous sides, and their linear cost per cluster (bincount: sums in row order)
    opp_rel = np.empty((R, 3))
    for r in range(R):
        for c in range(3):
            opp_rel[r, c] = opp[relevant[r], c]
    if has_sides:
        b_prev = _match(s_nodes, progress, opp_rel, prev_opp, prev_sides, node_dt, cluster_gap, safe_lat)
    else:
        b_prev = np.full(R, -1, dtype=np.int64)
    f_b = np.zeros(C)
    for r in range(R):
        if b_prev[r] >= 0:
            f_b[labels[r]] += w_switch * (1.0 - 2.0 * b_prev[r])

    # a car alongside keeps the ego on its side of it: its cluster's binary is fixed to that side
    b_fixed = empty_i
    if lock:
        any_along = False
        for r in range(R):
            any_along = any_along or along[r]
        if any_along:
            n_left = np.zeros(C, dtype=np.int64)
            count = np.zeros(C, dtype=np.int64)
            for r in range(R):
                if along[r]:
                    count[labels[r]] += 1
                    if ego_n > opp_rel[r, 1]:
                        n_left[labels[r]] += 1
            b_fixed = np.full(C, -1, dtype=np.int64)
            for c in range(C):
                if count[c] > 0 and n_left[c] == count[c]:
                    b_fixed[c] = 1
                elif count[c] > 0 and n_left[c] == 0:
                    b_fixed[c] = 0

    # active pairs, in the row-major order of nonzero()
    P = 0
    for r in range(R):
        for k in range(N):
            if act[r, k]:
                P += 1
    pair_k = np.empty(P, dtype=np.int64)
    pair_c = np.empty(P, dtype=np.int64)
    pair_r = np.empty(P, dtype=np.int64)
    pair_n = np.empty(P)
    pair_w = np.empty(P)
    p = 0
    for r in range(R):
        for k in range(N):
            if act[r, k]:
                pair_k[p], pair_r[p], pair_c[p] = k, r, labels[r]
                pair_n[p] = opp_rel[r, 1]
                pair_w[p] = clear[relevant[r], k]
                p += 1
    problem = (C, labels, p_lo, p_hi, d_prev, f_d, b_prev, f_b, b_fixed, pair_k, pair_c, pair_n, pair_w, pair_r)
    return PROBLEM, lo, hi, relevant, problem


@kernel
def finish_plan(d, b, prob_bounds, pairs, rel_cluster, b_prev, relevant, M):
    """What :meth:`~sofar_env.planning.miqp.PassingSidePlanner.plan` takes from a solution ``(d, b)`` in one
    compiled call: ``d`` clipped into ``prob_bounds = (lo, hi)`` (``np.clip``'s formula: nan kept, ties to the
    bound), the minimal slack per pair and the number of side switches (:func:`~.problem._slack_and_switch`),
    the sides per input opponent (+1 left where ``b > 0.5``, -1 right, 0 not relevant), the largest slack per
    opponent and over all pairs (0 without pairs). ``pairs = (pair_k, pair_c, pair_n, pair_w, pair_r)``.
    Returns ``(d, xi, switch, sides, opponent_slack, max_slack)``."""
    lo, hi = prob_bounds
    pair_k, pair_c, pair_n, pair_w, pair_r = pairs
    N = d.shape[0]
    out = np.empty(N)
    for k in range(N):
        x = d[k]
        if x == x:
            x = x if x > lo[k] else lo[k]
        if x == x:
            x = x if x < hi[k] else hi[k]
        out[k] = x
    xi, switch = _slack_and_switch(b, out, pair_c, pair_k, pair_n, pair_w, rel_cluster, b_prev)
    sides = np.zeros(M, dtype=np.int64)
    for r in range(relevant.shape[0]):
        sides[relevant[r]] = 1 if b[rel_cluster[r]] > 0.5 else -1
    opp_slack = np.zeros(M)
    top = 0.0
    for p in range(xi.shape[0]):
        i = relevant[pair_r[p]]
        opp_slack[i] = maximum(opp_slack[i], xi[p])
        top = maximum(top, xi[p])
    return out, xi, switch, sides, opp_slack, top
