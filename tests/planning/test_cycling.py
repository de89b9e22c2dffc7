"""DAQP's cycling exit in the passing planner's QPs (``MIQPConfig.daqp_cycle_tol``).

Two planner problems recorded in a 4-car race of the default controller (Indianapolis, gamma 0.5), where a
car runs alongside the ego over the whole horizon: a clearance row at nearly every node, and DAQP's active
set makes more than 10 steps without progress. With DAQP's default ``cycle_tol`` = 10 both routes give up
(the planner then falls back to its previous plan); with 100 both solve, agree, and find the optimum an
interior-point solver (PIQP) finds for each side pattern. Only the vectors are stored: the cost factors
are the default planner's (``cost_factors``).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import piqp
import pytest

from sofar_env.configs.registry import stack_preset
from sofar_env.errors import ConfigError
from sofar_env.planning import MIQPConfig, solvers
from sofar_env.planning.problem import SideProblem, cost_factors

DATA = Path(__file__).parent / "data" / "cycling_problems.npz"
CFG = stack_preset("sofar-13").miqp
SIDES = {"one": [0.0], "two": [1.0, 0.0]}
"""The sides of the optimum (1 left, 0 right): the cheap side, the one whose QP DAQP gave up on at 10."""


def _problem(tag: str) -> SideProblem:
    z = np.load(DATA)
    get = {k[len(tag) + 1:]: z[k] for k in z.files if k.startswith(tag + "_")}
    Rinv, RinvT = cost_factors(CFG)[True]  # both recorded with a previous plan
    return SideProblem(lo=get["lo"], hi=get["hi"], f_d=get["f_d"], Rinv=Rinv, RinvT=RinvT, pair_k=get["pair_k"],
                       pair_c=get["pair_c"], pair_n=get["pair_n"], pair_w=get["pair_w"], pair_r=get["pair_r"],
                       n_clusters=int(get["n_clusters"]), f_b=get["f_b"], n_ref=get["n_ref"], d_prev=get["d_prev"],
                       b_prev=get["b_prev"], rel_cluster=get["rel_cluster"], b_fixed=get["b_fixed"],
                       w_diag=CFG.w_dev + CFG.w_prev, w_smooth=CFG.w_smooth)


def _piqp_best(prob: SideProblem, w_slack: float) -> tuple[float, np.ndarray]:
    """The cheapest free side pattern and its objective, each pattern's QP (x = [xi, u]) solved by PIQP."""
    C, N, P = prob.n_clusters, prob.lo.size, prob.pair_k.size
    H = np.diag(np.concatenate([np.full(P, solvers._Q_SLACK), np.ones(N)]))
    f = np.concatenate([np.full(P, w_slack), prob.RinvT @ prob.f_d])
    best = (np.inf, None)
    for pattern in range(1 << C):
        b = np.array([(pattern >> c) & 1 for c in range(C)], float)
        if np.any((prob.b_fixed >= 0) & (b != prob.b_fixed)):
            continue
        left = b[prob.pair_c] > 0.5
        G = np.zeros((N + P, P + N))
        G[:N, P:] = prob.Rinv
        G[N:, P:] = prob.Rinv[prob.pair_k]
        G[N + np.arange(P), np.arange(P)] = np.where(left, 1.0, -1.0)
        h_l = np.concatenate([prob.lo, np.where(left, prob.pair_n + prob.pair_w, -np.inf)])
        h_u = np.concatenate([prob.hi, np.where(left, np.inf, prob.pair_n - prob.pair_w)])
        x_l = np.concatenate([np.zeros(P), np.full(N, -np.inf)])
        solver = piqp.DenseSolver()
        solver.settings.eps_abs = solver.settings.eps_rel = 1e-10
        solver.setup(np.asfortranarray(H), f, None, None, np.asfortranarray(G), h_l, h_u, x_l, None)
        assert solver.solve() == piqp.PIQP_SOLVED
        cost = float(solver.result.info.primal_obj) + float(prob.f_b @ b)
        if cost < best[0]:
            best = (cost, b)
    return best


@pytest.mark.parametrize("tag", ["one", "two"])
def test_at_the_default_limit_daqp_gives_up(tag):
    prob = _problem(tag)
    assert solvers.solve_branch_and_bound(prob, CFG.w_slack, {}, CFG.daqp_cycle_tol) is None
    assert solvers.solve_enumeration(prob, CFG.w_slack, CFG.daqp_cycle_tol) is None


@pytest.mark.parametrize("tag", ["one", "two"])
def test_a_higher_limit_solves_to_the_interior_point_optimum(tag):
    prob = _problem(tag)
    bnb = solvers.solve_branch_and_bound(prob, CFG.w_slack, {}, 100)
    enum = solvers.solve_enumeration(prob, CFG.w_slack, 100)
    assert bnb is not None and enum is not None
    np.testing.assert_array_equal(bnb[1], SIDES[tag])
    np.testing.assert_array_equal(enum[1], SIDES[tag])
    np.testing.assert_allclose(bnb[0], enum[0], atol=1e-6)
    cost, sides = _piqp_best(prob, CFG.w_slack)
    np.testing.assert_array_equal(sides, SIDES[tag])
    d = enum[0]
    assert np.all(d >= prob.lo - 1e-6) and np.all(d <= prob.hi + 1e-6)  # the corridor holds
    # the plan's objective, as the enumeration's QP counts it (slacks at their optimum: the clearance shortfall)
    left = sides[prob.pair_c] > 0.5
    xi = np.where(left, prob.pair_n + prob.pair_w - d[prob.pair_k], d[prob.pair_k] - (prob.pair_n - prob.pair_w))
    xi = np.maximum(xi, 0.0)
    u = np.linalg.solve(prob.Rinv, d)
    obj = (0.5 * solvers._Q_SLACK * xi @ xi + CFG.w_slack * xi.sum() + 0.5 * u @ u + (prob.RinvT @ prob.f_d) @ u
           + float(prob.f_b @ sides))
    assert obj == pytest.approx(cost, rel=1e-6, abs=1e-4)


def test_the_limit_is_a_neutral_validated_setting():
    from sofar_env.config_hash import config_hash

    base = stack_preset("sofar-13")
    assert MIQPConfig().daqp_cycle_tol == 10
    raised = dataclasses.replace(base, miqp=dataclasses.replace(base.miqp, daqp_cycle_tol=10))
    assert config_hash(raised) == config_hash(base)  # its default adds nothing to the hash
    raised = dataclasses.replace(base, miqp=dataclasses.replace(base.miqp, daqp_cycle_tol=100))
    assert config_hash(raised) != config_hash(base)
    for bad in (0, -5, 2.5, True, float("nan"), "100"):
        with pytest.raises(ConfigError, match="daqp_cycle_tol"):
            MIQPConfig(daqp_cycle_tol=bad)
