"""The passing-side problem built in one compiled call (sofar_env.planning.build) against the numpy form it
replaced, bit for bit."""

from __future__ import annotations

import numpy as np
import pytest

from sofar_env.planning import MIQPConfig, PassingSidePlanner
from sofar_env.planning.build import NO_OPPONENTS, PROBLEM, build_problem
from sofar_env.planning.clearance import side_clusters
from sofar_env.planning.hysteresis import match_previous_sides

from .instances import random_instance


def _reference(planner, s_nodes, n_ref, n_min, n_max, ego_n, opp, opp_s, progress):
    """The numpy form of the planner's build before it was compiled: (status, lo, hi, relevant, problem)."""
    cfg = planner.config
    lo = n_min + cfg.track_margin
    hi = n_max - cfg.track_margin
    cross = lo > hi
    lo[cross] = hi[cross] = 0.5 * (n_min[cross] + n_max[cross])
    clear = planner._window.clearance(s_nodes, opp_s)
    active = clear > 0.0
    relevant = active.any(axis=1).nonzero()[0]
    if relevant.size == 0:
        return NO_OPPONENTS, lo, hi, relevant, None
    opp_rel = opp[relevant]
    act_rel = active[relevant]
    along = apart = None
    if cfg.alongside_gap > 0.0:
        along = np.abs(opp_rel[:, 0]) < cfg.alongside_gap
        left = opp_rel[:, 1] > ego_n
        apart = along[:, None] & along[None, :] & (left[:, None] != left[None, :])
    n_clusters, labels = side_clusters(opp_s[relevant], act_rel, cfg.cluster_gap, apart)
    p_lo, p_hi = lo.copy(), hi.copy()
    lo_0, hi_0 = float(lo[0]), float(hi[0])
    e = min(max(ego_n, lo_0), hi_0)
    p_lo[0] = max(lo_0, e - cfg.continuity)
    p_hi[0] = min(hi_0, e + cfg.continuity)
    d_prev = None if planner._prev_d is None else np.interp(s_nodes + progress, planner._prev_s, planner._prev_d)
    if d_prev is None:
        f_d = -2.0 * cfg.w_dev * n_ref
    else:
        f_d = -2.0 * (cfg.w_dev * n_ref + cfg.w_prev * d_prev)
    b_prev = match_previous_sides(cfg, s_nodes, progress, opp_rel, planner._prev_opp, planner._prev_sides)
    known = b_prev >= 0
    f_b = np.bincount(labels[known], weights=cfg.w_switch * (1.0 - 2.0 * b_prev[known]), minlength=n_clusters)
    b_fixed = None
    if along is not None and along.any():
        b_now = (ego_n > opp_rel[along, 1]).astype(int)
        n_left = np.bincount(labels[along], weights=b_now, minlength=n_clusters)
        count = np.bincount(labels[along], minlength=n_clusters)
        b_fixed = np.full(n_clusters, -1, dtype=int)
        b_fixed[(count > 0) & (n_left == count)] = 1
        b_fixed[(count > 0) & (n_left == 0)] = 0
    rows, ks = act_rel.nonzero()
    problem = (n_clusters, labels, p_lo, p_hi, d_prev, f_d, b_prev, f_b, b_fixed, ks, labels[rows], opp_rel[rows, 1],
               clear[relevant[rows], ks], rows)
    return PROBLEM, lo, hi, relevant, problem


@pytest.mark.parametrize("alongside_gap", [0.0, 8.0])
def test_the_compiled_build_is_the_numpy_form(alongside_gap):
    """Random closed-loop-like sequences (previous plans and sides, cars alongside, a standing ego whose nodes
    repeat): every value of the compiled build equals the numpy form's, bit for bit."""
    rng = np.random.default_rng(7 if alongside_gap else 8)
    planner = PassingSidePlanner(MIQPConfig(alongside_gap=alongside_gap, closing_decel=6.0))
    built = {NO_OPPONENTS: 0, PROBLEM: 0}
    locked = with_plan = 0
    for trial in range(10):
        s, n_ref, n_min, n_max, ego_n, opp = random_instance(rng, min_gap=2.0)
        if trial == 3:
            s = np.minimum(s, s[20])  # the ego stops: nodes repeat
        planner.reset()
        for _ in range(5):
            opp_s = opp[:, :1] + opp[:, 2:3] * planner._t[None, :]
            progress = float(rng.uniform(0.0, 8.0))
            args = (s, n_ref, n_min, n_max, float(ego_n), opp, opp_s, progress)
            want = _reference(planner, *args)
            got = build_problem((s, n_ref, n_min, n_max), opp, opp_s, (float(ego_n), progress),
                                planner._previous(), planner._weights, planner._window_args, False)
            assert got[0] == want[0]
            built[got[0]] += 1
            for g, w in zip(got[1:4], want[1:4]):
                np.testing.assert_array_equal(g, w)
            if want[0] == PROBLEM:
                for i, (g, w) in enumerate(zip(got[4], want[4])):
                    if w is None:
                        assert np.size(g) == 0, i
                    else:
                        np.testing.assert_array_equal(g, w, err_msg=str(i))
                locked += want[4][8] is not None
                with_plan += want[4][4] is not None
            plan = planner.plan(s, n_ref, n_min, n_max, ego_n, opp, progress=progress, opponent_s=opp_s)
            ego_n = float(plan.lateral_at(progress))
            opp = opp.copy()
            opp[:, 0] -= rng.uniform(0.0, 5.0)
    assert built[PROBLEM] > 20 and with_plan > 10
    assert locked > 0 or not alongside_gap


def test_the_compiled_finish_is_the_numpy_form():
    """The solutions of closed-loop-like problems, and the same moved outside their bounds, with nan and signed
    zeros on the bounds: clipped plan, slacks, switch count, sides and slack maxima of the compiled finish equal
    the numpy form's (np.clip, the slack kernel, np.where, np.maximum.at, np.maximum.reduce), bit for bit."""
    from numpy._core.umath import clip

    from sofar_env.planning.build import finish_plan
    from sofar_env.planning.problem import _slack_and_switch

    from .test_solvers import _closed_loop_problems

    rng = np.random.default_rng(17)
    seen = _closed_loop_problems(seed=19, alongside_gap=8.0)
    assert len(seen) > 15
    for trial, (prob, _, out) in enumerate(seen):
        d, b = out[0].copy(), out[1]
        if trial % 3 == 1:
            d += rng.normal(size=d.size)
            d[int(rng.integers(d.size))] = np.nan
            d[0] = -0.0
            prob.lo[0] = 0.0
        M = int(prob.pair_r.max(initial=0)) + 2
        relevant = np.arange(prob.rel_cluster.size) + 1
        got = finish_plan(d, b, (prob.lo, prob.hi), (prob.pair_k, prob.pair_c, prob.pair_n, prob.pair_w, prob.pair_r),
                          prob.rel_cluster, prob.b_prev, relevant, M)
        d_w = clip(d, prob.lo, prob.hi)
        xi, switch = _slack_and_switch(b, d_w, prob.pair_c, prob.pair_k, prob.pair_n, prob.pair_w, prob.rel_cluster,
                                       prob.b_prev)
        sides = np.zeros(M, dtype=int)
        sides[relevant] = np.where(b[prob.rel_cluster] > 0.5, 1, -1)
        opp_slack = np.zeros(M)
        np.maximum.at(opp_slack, relevant[prob.pair_r], xi)
        want = (d_w, xi, switch, sides, opp_slack, float(np.maximum.reduce(xi, initial=0.0)))
        for i, (g, w) in enumerate(zip(got, want)):
            np.testing.assert_array_equal(g, w, err_msg=str(i))
            assert np.signbit(g).tolist() == np.signbit(w).tolist(), i
