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
    cached = {k: tuple(np.copy(a) for a in v) for k, v in planner._bnb_cache.items()}
    planner.reset()
    again = planner.plan(s, n_ref, n_min, n_max, 0.0, opp)
    for k, v in planner._bnb_cache.items():
        for a, b in zip(v, cached[k]):
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


def test_the_compiled_branch_and_bound_data_are_the_numpy_form():
    """Every problem the planner builds on random closed-loop-like sequences (with sides pinned by cars
    alongside among them): the compiled data of the DAQP call equal the numpy form, bit for bit."""
    from sofar_env.planning import solvers

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

    def keep(prob, w_slack, cache):
        problems.append((prob, w_slack))
        return original_solve(prob, w_slack, cache)

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
