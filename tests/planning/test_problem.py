"""Tests of the MIQP problem data and its exact cost (sofar_env.planning.problem)."""

from __future__ import annotations

import numpy as np
import pytest

from sofar_env.planning import MIQPConfig
from sofar_env.planning.problem import SLACK_TOL, SideProblem, cost_factors, evaluate, plan_cost


@pytest.mark.parametrize("cfg", [MIQPConfig(), MIQPConfig(nodes=9, w_dev=2.0, w_smooth=3.0, w_prev=0.5)])
def test_cost_factors_whiten_the_lateral_hessian(cfg):
    """R^-T H_d R^-1 = I, with H_d the Hessian of the lateral cost (with and without w_prev)."""
    N = cfg.nodes
    D = np.diff(np.eye(N), axis=0)
    factors = cost_factors(cfg)
    for with_prev, (Rinv, RinvT) in factors.items():
        H = 2.0 * (cfg.w_dev * np.eye(N) + cfg.w_smooth * D.T @ D + (cfg.w_prev * np.eye(N) if with_prev else 0.0))
        np.testing.assert_array_equal(RinvT, Rinv.T)
        np.testing.assert_allclose(RinvT @ H @ Rinv, np.eye(N), atol=1e-9)
        np.testing.assert_array_equal(np.tril(Rinv, -1), 0.0)  # inverse of an upper triangular factor


def test_plan_cost_is_the_quadratic_form():
    cfg = MIQPConfig(nodes=5, w_dev=2.0, w_smooth=3.0, w_prev=0.5)
    rng = np.random.default_rng(0)
    d, n_ref, d_prev = rng.normal(size=(3, 5))
    # 0.5 d'Hd + f'd + const equals the sum of the weighted squares
    D = np.diff(np.eye(5), axis=0)
    H = 2.0 * (cfg.w_dev * np.eye(5) + cfg.w_smooth * D.T @ D + cfg.w_prev * np.eye(5))
    f = -2.0 * (cfg.w_dev * n_ref + cfg.w_prev * d_prev)
    const = cfg.w_dev * n_ref @ n_ref + cfg.w_prev * d_prev @ d_prev
    assert plan_cost(cfg, d, n_ref, d_prev, 7.0, 11.0) == pytest.approx(0.5 * d @ H @ d + f @ d + const + 18.0)
    assert plan_cost(cfg, d, n_ref, None, 0.0, 0.0) < plan_cost(cfg, d, n_ref, d_prev, 0.0, 0.0)


def test_evaluate_uses_the_minimal_slack_and_the_switch_cost():
    cfg = MIQPConfig(nodes=4)
    N = cfg.nodes
    prob = SideProblem(lo=-np.ones(N), hi=np.ones(N), f_d=np.zeros(N), Rinv=np.eye(N), RinvT=np.eye(N),
                       pair_k=np.array([1, 2, 3]), pair_c=np.array([0, 0, 1]),
                       pair_n=np.array([-3.0, -3.0, 3.0]), pair_w=np.array([3.75, 3.75, 3.75]),
                       pair_r=np.array([0, 0, 1]), n_clusters=2, f_b=np.zeros(2), n_ref=np.zeros(N),
                       d_prev=None, b_prev=np.array([1, 1]), rel_cluster=np.array([0, 1]))
    d = np.array([0.0, 0.75 - 0.5 * SLACK_TOL, 0.5, -0.75])
    b = np.array([1.0, 0.0])  # cluster 0 left (d >= n + w = 0.75), cluster 1 right (d <= -0.75)
    obj, xi = evaluate(cfg, prob, d, b)
    np.testing.assert_allclose(xi, [0.0, 0.25, 0.0])  # below the tolerance counts as zero
    switch = cfg.w_switch * 1.0  # opponent 1 was passed on the left before
    assert obj == pytest.approx(plan_cost(cfg, d, prob.n_ref, None, switch, cfg.w_slack * 0.25))
