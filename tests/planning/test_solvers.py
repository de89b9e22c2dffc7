"""Tests of the DAQP solver routes of the MIQP (sofar_env.planning.solvers)."""

from __future__ import annotations

import numpy as np
import pytest

from sofar_env.planning import MIQPConfig, PassingSidePlanner

from .instances import CFG, random_instance, straight


def test_daqp_and_enumeration_agree_with_memory():
    """Closed-loop-like sequences: consistency and hysteresis terms active."""
    rng = np.random.default_rng(3)
    p_bnb = PassingSidePlanner(MIQPConfig(solver="daqp"))
    p_enum = PassingSidePlanner(MIQPConfig(solver="enumerate"))
    solved = 0
    for _ in range(4):
        s, n_ref, n_min, n_max, ego_n, opp = random_instance(rng, min_gap=25.0)
        v = s[1] / CFG.node_dt
        p_bnb.reset()
        p_enum.reset()
        progress = 0.0
        for _ in range(8):
            a = p_bnb.plan(s, n_ref, n_min, n_max, ego_n, opp, progress=progress)
            b = p_enum.plan(s, n_ref, n_min, n_max, ego_n, opp, progress=progress)
            assert a.success and b.success
            np.testing.assert_array_equal(a.sides, b.sides)
            assert a.objective == pytest.approx(b.objective, rel=1e-6, abs=1e-6)
            progress = 0.15 * v
            ego_n = float(a.lateral_at(progress))
            opp = opp.copy()
            opp[:, 0] += (opp[:, 2] - v) * 0.15
            solved += a.status == "optimal"
    assert solved > 10


def test_solver_inputs_are_not_shared_between_calls():
    """The cached Hessian and constraint types of the branch-and-bound are reused unchanged."""
    s, n_ref, n_min, n_max = straight()
    planner = PassingSidePlanner()
    opp = np.array([[30.0, 0.5, 40.0], [45.0, -2.0, 42.0]])
    first = planner.plan(s, n_ref, n_min, n_max, 0.0, opp)
    from sofar_env.planning.solvers import _WORKSPACE

    cached = {k: tuple(np.copy(a) for a in v) for k, v in planner._bnb_cache.items() if k != _WORKSPACE}
    planner.reset()
    again = planner.plan(s, n_ref, n_min, n_max, 0.0, opp)
    for k, v in cached.items():
        for a, b in zip(planner._bnb_cache[k], v):
            np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(first.sides, again.sides)
    np.testing.assert_allclose(first.d, again.d, atol=1e-9)


def numpy_bnb_data(prob, w_slack):
    """The branch-and-bound data as numpy expressions (f, A, bupper, blower)."""
    from sofar_env.planning.solvers import _INF, _Q_BIN

    C, N, P = prob.n_clusters, prob.lo.size, prob.pair_k.size
    nv = C + P + N
    sl = prob.pair_w
    lo_k, hi_k = prob.lo[prob.pair_k], prob.hi[prob.pair_k]
    Ma = np.maximum(0.0, hi_k - prob.pair_n + sl)
    Mb = np.maximum(0.0, prob.pair_n + sl - lo_k)
    f = np.empty(nv)
    f[:C] = prob.f_b - 0.5 * _Q_BIN
    f[C:C + P] = w_slack
    f[C + P:] = prob.RinvT @ prob.f_d
    A = np.zeros((N + 2 * P, nv))
    A[:N, C + P:] = prob.Rinv
    A[N:, C + P:] = prob.Rinv[np.concatenate([prob.pair_k, prob.pair_k])]
    rows2 = N + np.arange(2 * P)
    A[rows2, np.concatenate([prob.pair_c, prob.pair_c])] = -np.concatenate([Ma, Mb])
    A[rows2, C + np.concatenate([np.arange(P), np.arange(P)])] = np.concatenate([-np.ones(P), np.ones(P)])
    bupper = np.full(C + P + N + 2 * P, _INF)
    blower = np.zeros(C + P + N + 2 * P)
    bupper[:C] = 1.0
    if prob.b_fixed is not None:
        fixed = prob.b_fixed >= 0
        bupper[:C] = np.where(fixed, prob.b_fixed, 1.0)
        blower[:C] = np.where(fixed, prob.b_fixed, 0.0)
    bupper[C + P:C + P + N] = prob.hi
    blower[C + P:C + P + N] = prob.lo
    bupper[C + P + N:C + 2 * P + N] = prob.pair_n - sl
    blower[C + P + N:C + 2 * P + N] = -_INF
    blower[C + 2 * P + N:] = prob.pair_n + sl - Mb
    return f, A, bupper, blower


def test_the_compiled_branch_and_bound_data_are_the_numpy_form(monkeypatch):
    """Every problem the planner builds on random closed-loop-like sequences (with sides pinned by cars
    alongside among them): the compiled data of the DAQP call equal the numpy form, bit for bit (on the
    Python route, whose data kernel the compiled route calls)."""
    from sofar_env.planning import solvers

    monkeypatch.setattr(solvers, "NATIVE", False)

    captured = []
    real = solvers._bnb_data

    def spy(*args):
        out = real(*args)
        captured.append((args, out))
        return out

    rng = np.random.default_rng(11)
    planner = PassingSidePlanner(MIQPConfig(alongside_gap=8.0))
    problems = []
    original_solve = solvers.solve_branch_and_bound

    def keep(prob, w_slack, cache, *settings):
        problems.append((prob, w_slack))
        return original_solve(prob, w_slack, cache, *settings)

    solvers._bnb_data = spy
    try:
        import sofar_env.planning.miqp as miqp
        kept = miqp.solve_branch_and_bound
        miqp.solve_branch_and_bound = keep
        for _ in range(6):
            s, n_ref, n_min, n_max, ego_n, opp = random_instance(rng, min_gap=2.0)
            planner.reset()
            for _ in range(4):
                planner.plan(s, n_ref, n_min, n_max, ego_n, opp, progress=5.0)
                opp = opp.copy()
                opp[:, 0] -= 3.0
    finally:
        solvers._bnb_data = real
        miqp.solve_branch_and_bound = kept
    assert len(problems) == len(captured) > 10
    assert any(p.b_fixed is not None and (p.b_fixed >= 0).any() for p, _ in problems)
    for (prob, w_slack), (_, got) in zip(problems, captured):
        for name, g, w in zip(("f", "A", "bupper", "blower"), got, numpy_bnb_data(prob, w_slack)):
            np.testing.assert_array_equal(g, w, err_msg=name)


def _closed_loop_problems(seed: int, alongside_gap: float = 0.0, calls: int = 6):
    """The problems the planner hands to the branch-and-bound on random closed-loop-like sequences (the
    previous plan and sides known from the second call on), with the solver's own result for each."""
    from sofar_env.planning import miqp, solvers

    rng = np.random.default_rng(seed)
    planner = PassingSidePlanner(MIQPConfig(alongside_gap=alongside_gap))
    seen = []
    original = solvers.solve_branch_and_bound

    def keep(prob, w_slack, cache, *settings):
        out = original(prob, w_slack, cache, *settings)
        seen.append((prob, w_slack, out))
        return out

    kept = miqp.solve_branch_and_bound
    miqp.solve_branch_and_bound = keep
    try:
        for _ in range(calls):
            s, n_ref, n_min, n_max, ego_n, opp = random_instance(rng, min_gap=5.0)
            planner.reset()
            for _ in range(5):
                plan = planner.plan(s, n_ref, n_min, n_max, ego_n, opp, progress=6.0)
                ego_n = float(plan.lateral_at(6.0))
                opp = opp.copy()
                opp[:, 0] -= 4.0
    finally:
        miqp.solve_branch_and_bound = kept
    return seen


def _daqp_objective(prob, w_slack, d, b):
    """DAQP's objective 0.5 x'Hx + f'x of x = [b, xi, u = R d], xi the minimal slacks at (d, b), in numpy."""
    from sofar_env.planning.solvers import _Q_BIN, _Q_SLACK

    C = prob.n_clusters
    f = numpy_bnb_data(prob, w_slack)[0]
    u = np.linalg.solve(prob.Rinv, d)
    lo_k, hi_k = prob.lo[prob.pair_k], prob.hi[prob.pair_k]
    Ma = np.maximum(0.0, hi_k - prob.pair_n + prob.pair_w)
    Mb = np.maximum(0.0, prob.pair_n + prob.pair_w - lo_k)
    bc = b[prob.pair_c]
    xi = np.maximum.reduce([np.zeros(len(bc)), d[prob.pair_k] - Ma * bc - (prob.pair_n - prob.pair_w),
                            prob.pair_n + prob.pair_w - Mb + Mb * bc - d[prob.pair_k]])
    x = np.concatenate([b, xi, u])
    h = np.concatenate([np.full(C, _Q_BIN), np.full(len(xi), _Q_SLACK), np.ones(len(u))])
    return 0.5 * float(x @ (h * x)) + float(f @ x)


def test_the_incumbent_bound_is_a_feasible_objective_above_the_optimum():
    """The bound handed to DAQP is the objective of a feasible point (evaluated in d, it equals DAQP's
    objective in x = [b, xi, u]): it is never below the optimum, and close to it in closed loop."""
    from sofar_env.planning.solvers import _INF, _incumbent_bound

    seen = _closed_loop_problems(seed=5, alongside_gap=8.0)
    gaps = []
    for prob, w_slack, out in seen:
        assert out is not None
        d_opt, b_opt = out
        C = prob.n_clusters
        b_fixed = prob.b_fixed if prob.b_fixed is not None else np.zeros(0, dtype=np.int64)
        f = numpy_bnb_data(prob, w_slack)[0]
        start = prob.d_prev if prob.d_prev is not None else prob.n_ref
        bound = _incumbent_bound(C, f, prob.f_d, prob.w_diag, prob.w_smooth, prob.lo, prob.hi, start,
                                 prob.pair_k, prob.pair_c, prob.pair_n, prob.pair_w, b_fixed)
        assert bound < _INF
        optimum = _daqp_objective(prob, w_slack, d_opt, b_opt)
        assert bound >= optimum - 1e-9 * (abs(optimum) + 1.0)
        gaps.append((bound - optimum) / (abs(optimum) + 1.0))
        # its lateral part, evaluated in d, is DAQP's objective in u = R d: compare on the problem without pairs
        empty = replace_w_diag(prob, prob.w_diag)
        empty.pair_k, empty.pair_c = np.zeros(0, np.int64), np.zeros(0, np.int64)
        empty.pair_n, empty.pair_w, empty.n_clusters, empty.f_b = np.zeros(0), np.zeros(0), 0, np.zeros(0)
        empty.b_fixed = None
        f0 = numpy_bnb_data(empty, w_slack)[0]
        lateral = _incumbent_bound(0, f0, prob.f_d, prob.w_diag, prob.w_smooth, prob.lo, prob.hi, start,
                                   empty.pair_k, empty.pair_c, empty.pair_n, empty.pair_w, b_fixed[:0])
        point = np.clip(start, prob.lo, prob.hi)
        expected = _daqp_objective(empty, w_slack, point, np.zeros(0))
        assert lateral == pytest.approx(expected + 1e-6 * (abs(expected) + 1.0), rel=1e-9, abs=1e-7)
    assert len(gaps) > 15
    assert np.median(gaps) < 0.1  # the previous plan, moved to each side, is nearly optimal


def test_the_incumbent_does_not_change_the_solution(monkeypatch):
    """With and without DAQP's fval_bound, the branch-and-bound returns the same values to the bit; a bound
    below the optimum (every node pruned) falls back to the search without it (on the Python route, where the
    bound can be replaced; tests/planning/test_daqp_c.py pins the compiled route to it)."""
    from sofar_env.planning import solvers

    monkeypatch.setattr(solvers, "NATIVE", False)

    seen = _closed_loop_problems(seed=9, alongside_gap=8.0)
    assert len(seen) > 15
    real = solvers._incumbent_bound
    try:
        for prob, w_slack, out in seen:
            plain = solvers.solve_branch_and_bound(replace_w_diag(prob, None), w_slack, {})
            for d_ref, d in zip(out, plain):
                np.testing.assert_array_equal(d, d_ref)
            solvers._incumbent_bound = lambda *args: -1e6  # below any objective of these problems
            low = solvers.solve_branch_and_bound(prob, w_slack, {})
            solvers._incumbent_bound = real
            for d_ref, d in zip(out, low):
                np.testing.assert_array_equal(d, d_ref)
    finally:
        solvers._incumbent_bound = real


def replace_w_diag(prob, w_diag):
    import dataclasses

    return dataclasses.replace(prob, w_diag=w_diag)


def test_plans_with_and_without_the_incumbent_are_identical():
    """Closed-loop-like sequences (cars alongside locking sides among them): the planner with the incumbent
    returns the same plans, sides and objectives, to the bit, as the planner without it."""
    rng = np.random.default_rng(21)
    with_bound = PassingSidePlanner(MIQPConfig(alongside_gap=8.0))
    plain = PassingSidePlanner(MIQPConfig(alongside_gap=8.0, incumbent=False))
    optimal = 0
    for _ in range(6):
        s, n_ref, n_min, n_max, ego_n, opp = random_instance(rng, min_gap=4.0)
        with_bound.reset()
        plain.reset()
        for _ in range(6):
            a = with_bound.plan(s, n_ref, n_min, n_max, ego_n, opp, progress=6.0)
            b = plain.plan(s, n_ref, n_min, n_max, ego_n, opp, progress=6.0)
            assert a.status == b.status
            np.testing.assert_array_equal(a.d, b.d)
            np.testing.assert_array_equal(a.sides, b.sides)
            assert a.objective == b.objective or (np.isnan(a.objective) and np.isnan(b.objective))
            optimal += a.status == "optimal"
            ego_n = float(a.lateral_at(6.0))
            opp = opp.copy()
            opp[:, 0] -= 4.0
    assert optimal > 15


def test_the_incumbent_bound_gives_up_on_many_side_decisions_and_non_finite_plans():
    """No bound (DAQP's infinity) with more side decisions than the patterns it tries, or when the previous plan
    is not finite; a finite bound otherwise."""
    from sofar_env.planning.solvers import _BOUND_MAX_CLUSTERS, _INF, _incumbent_bound

    n = 8
    no_pairs = (np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0), np.zeros(0))
    not_fixed = np.zeros(0, np.int64)

    def bound(C, start):  # C free side decisions, no active pairs, a corridor of +-1 m
        return _incumbent_bound(C, np.zeros(C + n), np.zeros(n), 1.0, 100.0, -np.ones(n), np.ones(n), start,
                                *no_pairs, not_fixed)

    assert bound(2, np.zeros(n)) < _INF
    assert bound(_BOUND_MAX_CLUSTERS, np.zeros(n)) < _INF
    assert bound(_BOUND_MAX_CLUSTERS + 1, np.zeros(n)) == _INF
    start = np.zeros(n)
    start[3] = np.nan
    assert bound(2, start) == _INF
