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
