"""``MPCDCBF.reference_solution``: IPOPT's solution from a chosen guess, with its objective, the MPC left as it was;
and the stall probe built on it (``sofar_agents.evaluation.stall_probe``)."""

from __future__ import annotations

import copy
import math

import numpy as np
import pytest

from sofar_agents.evaluation.stall_probe import ProbeRow, StallProbe, probe_problem
from sofar_env.control.barrier import barrier_table
from sofar_env.control.mpc import MPCConfig, MPCDCBF

from .scenarios import make_stage


def _parked_scene(cache_dir, horizon=20):
    """The ego at rest 6 m behind a car parked in its lane: inside the barrier's ellipse (h < 0)."""
    cfg = MPCConfig(cache_dir=cache_dir, horizon=horizon)
    x0 = np.array([0.0, 0.0, 0.0, 0.0, 0.0])
    opp = np.array([[6.0, 0.0, 0.0]])
    return cfg, x0, opp


def test_the_solution_reports_its_objective_and_leaves_the_mpc_as_it_was(cache_dir):
    cfg, x0, opp = _parked_scene(cache_dir)
    stage = make_stage(v_ref=10.0, n=cfg.horizon)
    mpc = MPCDCBF(cfg)
    mpc.solve(x0, stage, opp, 0.5)  # a warm start and counters to keep
    kept = (mpc._xg.copy(), mpc._ug.copy(), mpc.n_failures, mpc._plan_age)
    sol = mpc.reference_solution(x0, stage, opp, 0.5)
    assert sol.success and math.isfinite(sol.objective) and sol.objective > 0.0
    assert np.array_equal(mpc._xg, kept[0]) and np.array_equal(mpc._ug, kept[1])
    assert (mpc.n_failures, mpc._plan_age) == kept[2:]
    # the same problem from the same guess as solve_converged: the same plan
    twin = copy.deepcopy(mpc)
    assert np.array_equal(twin.solve_converged(x0, stage, opp, 0.5).x_pred, sol.x)


def test_a_plan_that_stands_inside_the_ellipse_pays_gamma_times_the_violation(cache_dir):
    """Standing keeps h = h0 < 0 at every stage, and the DCBF row h_{k+1} >= (1 - gamma) h_k then needs the slack
    gamma |h0| on every transition."""
    cfg, x0, opp = _parked_scene(cache_dir)
    stage = make_stage(v_ref=0.0, n=cfg.horizon)  # nothing to gain by moving
    h0 = barrier_table(x0[None, :], opp[None, :, :3], cfg.barrier)[2]
    assert h0 < 0.0
    for gamma in (0.3, 0.9):
        sol = MPCDCBF(cfg).reference_solution(x0, stage, opp, gamma, guess=(np.repeat(x0[None], cfg.horizon + 1, 0),
                                                                            np.zeros((cfg.horizon, 2))))
        assert sol.success and np.max(sol.x[:, 3]) < 1e-3
        np.testing.assert_allclose(sol.slack_barrier.max(), gamma * abs(h0), rtol=1e-5)


@pytest.mark.parametrize("guess, message", [
    ((np.zeros((20, 5)), np.zeros((20, 2))), "guess must be"),
    ((np.zeros((21, 5)), np.zeros((21, 2))), "guess must be"),
    ((np.full((21, 5), np.nan), np.zeros((20, 2))), "finite"),
])
def test_a_guess_of_another_shape_or_not_finite_is_refused(cache_dir, guess, message):
    cfg, x0, opp = _parked_scene(cache_dir)
    with pytest.raises(ValueError, match=message):
        MPCDCBF(cfg).reference_solution(x0, make_stage(n=cfg.horizon), opp, 0.5, guess=guess)


def test_the_probe_solves_every_horizon_from_every_guess_and_keeps_the_cheapest(cache_dir):
    cfg, x0, opp = _parked_scene(cache_dir)
    stage = make_stage(v_ref=10.0, n=cfg.horizon)

    def lookup(ego_s, s_rel):  # a straight, 12 m wide road
        k = len(s_rel)
        return ego_s + s_rel, np.zeros(k), np.full(k, 10.0), np.full(k, -6.0), np.full(k, 6.0)

    mpc = MPCDCBF(cfg)
    rows = probe_problem(mpc, stage, x0, opp, 0.5, lookup, 0.0, (20, 30))
    assert [(r.horizon, r.guess) for r in rows] == [(20, "own"), (20, "stand"), (20, "left"), (20, "right"),
                                                    (30, "stand"), (30, "left"), (30, "right")]
    assert all(r.success for r in rows) and mpc._xg is None  # the MPC probed is left as it was
    rti = ProbeRow(20, 1.5, "rti", True, 0.0, math.nan, 0.0, 0.0, 0.0, 0.1, math.nan)
    probe = StallProbe(None, 1.0, (0.0, 0.0, 0.0, 0.0), 20, (rti, *rows))
    for h in (20, 30):
        best = probe.best(h)
        assert best.objective == min(r.objective for r in rows if r.horizon == h)
    assert probe.verdict in ("rti", "waits", "horizon", "stands")


def _row(horizon, guess, moves, objective=1.0, starts=None):
    starts = moves if starts is None else starts
    return ProbeRow(horizon, horizon * 0.075, guess, True, 0.3 if starts else 0.0, 0.5 if moves else math.nan, 1.0,
                    0.0, 0.0, 0.0, objective)


@pytest.mark.parametrize("rows, verdict", [
    ([_row(20, "rti", True), _row(20, "own", False)], "drives"),
    ([_row(20, "rti", True, starts=False), _row(20, "own", True, starts=False)], "waits"),
    ([_row(20, "rti", False), _row(20, "own", True, 2.0), _row(20, "stand", False, 3.0)], "rti"),
    ([_row(20, "rti", False), _row(20, "own", True, 3.0), _row(20, "stand", False, 2.0)], "stands"),
    ([_row(20, "rti", False), _row(20, "own", False), _row(40, "stand", False, 1.0), _row(40, "left", True, 2.0)],
     "stands"),
    ([_row(20, "rti", False), _row(20, "own", False), _row(40, "stand", False, 2.0), _row(40, "left", True, 1.0)],
     "horizon"),
])
def test_the_verdict_reads_the_cheapest_solution_of_each_horizon(rows, verdict):
    assert StallProbe(None, 1.0, (0.0,) * 4, 20, tuple(rows)).verdict == verdict
