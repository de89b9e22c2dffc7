"""Tests of the passing-side planner (sofar_env.planning.miqp): optimality against an independent
brute force, side decisions, bounds, special cases and robustness."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

import sofar_env.planning.solvers as solvers_mod
from sofar_env.planning import MIQPConfig, PassingSidePlanner, PlanResult

from .instances import CFG, HALF_WIDTH, N, random_instance, straight


# --------------------------------------------------------------------------
# An independent brute force: own activation, clusters and cost, QPs by PIQP.
# --------------------------------------------------------------------------
def bf_activation(s, opp, cfg):
    t = cfg.node_dt * np.arange(cfg.nodes)
    gap = opp[:, [0]] + opp[:, [2]] * t - s
    act = np.zeros(gap.shape, dtype=bool)
    for i in range(gap.shape[0]):
        for k in range(cfg.nodes - 1):
            a, b = gap[i, k], gap[i, k + 1]
            if min(a, b) < cfg.safe_lon and max(a, b) > -cfg.safe_lon:
                act[i, k] = act[i, k + 1] = True
        act[i] |= np.abs(gap[i]) < cfg.safe_lon
    return act


def bf_linked(oi, oj, act_i, act_j, cfg):
    t = cfg.node_dt * np.arange(cfg.nodes)
    dist = np.abs(oi[0] - oj[0] + (oi[2] - oj[2]) * t)
    return bool(np.any((dist < cfg.cluster_gap) & (act_i | act_j)))


def bf_cost(d, n_ref, xi, cfg):
    return (cfg.w_dev * np.sum((d - n_ref) ** 2) + cfg.w_smooth * np.sum(np.diff(d) ** 2)
            + cfg.w_slack * np.sum(xi))


def bf_solve(s, n_ref, n_min, n_max, ego_n, opp, cfg):
    """Best (objective, sides) over every cluster-consistent side pattern (fresh planner)."""
    import piqp

    lo, hi = n_min + cfg.track_margin, n_max - cfg.track_margin
    e = np.clip(ego_n, lo[0], hi[0])
    lo[0], hi[0] = max(lo[0], e - cfg.continuity), min(hi[0], e + cfg.continuity)
    act = bf_activation(s, opp, cfg)
    rel = [i for i in range(len(opp)) if act[i].any()]
    pairs = [(i, k) for i in rel for k in np.flatnonzero(act[i])]
    P = len(pairs)
    D = np.diff(np.eye(N), axis=0)
    Hq = np.zeros((N + P, N + P))
    Hq[:N, :N] = 2 * (cfg.w_dev * np.eye(N) + cfg.w_smooth * D.T @ D)
    c = np.concatenate([-2 * cfg.w_dev * n_ref, cfg.w_slack * np.ones(P)])
    best = (np.inf, None)
    for bits in itertools.product((1, -1), repeat=len(rel)):
        side = dict(zip(rel, bits))
        if any(side[i] != side[j] for i, j in itertools.combinations(rel, 2)
               if bf_linked(opp[i], opp[j], act[i], act[j], cfg)):
            continue  # not cluster-consistent (a sufficient check for chains of 2-4)
        G = np.zeros((P, N + P))
        h = np.zeros(P)
        for p, (i, k) in enumerate(pairs):
            if side[i] > 0:   # -d_k - xi <= -(n_i + safe_lat)
                G[p, k], h[p] = -1.0, -(opp[i, 1] + cfg.safe_lat)
            else:             # d_k - xi <= n_i - safe_lat
                G[p, k], h[p] = 1.0, opp[i, 1] - cfg.safe_lat
            G[p, N + p] = -1.0
        solver = piqp.DenseSolver()
        solver.settings.eps_abs = 1e-10
        solver.settings.eps_rel = 1e-11
        solver.setup(np.asfortranarray(Hq), c, None, None, np.asfortranarray(G) if P else None,
                     None, h if P else None,
                     np.concatenate([lo, np.zeros(P)]), np.concatenate([hi, np.full(P, np.inf)]))
        solver.solve()
        x = solver.result.x
        d = np.clip(x[:N], lo, hi)
        xi = np.array([max(0.0, (opp[i, 1] + cfg.safe_lat - d[k]) if side[i] > 0
                           else (d[k] - opp[i, 1] + cfg.safe_lat)) for i, k in pairs])
        xi[xi < 1e-6] = 0.0
        obj = bf_cost(d, n_ref, xi, cfg)
        if obj < best[0]:
            sides = np.zeros(len(opp), dtype=int)
            for i in rel:
                sides[i] = side[i]
            best = (obj, sides)
    return best


@pytest.mark.parametrize("solver", ["daqp", "enumerate"])
def test_optimum_equals_brute_force(solver):
    rng = np.random.default_rng(7)
    cfg = MIQPConfig(solver=solver)
    checked = with_binaries = 0
    for _ in range(14):
        inst = random_instance(rng, min_gap=5.0)
        res = PassingSidePlanner(cfg).plan(*inst)
        assert res.success
        if res.status == "no_opponents":
            continue
        obj, sides = bf_solve(*[np.array(a, copy=True) if isinstance(a, np.ndarray) else a
                                for a in inst], cfg)
        assert res.objective == pytest.approx(obj, rel=1e-6, abs=1e-6)
        np.testing.assert_array_equal(res.sides, sides)
        checked += 1
        with_binaries += res.n_binaries >= 2
    assert checked >= 10 and with_binaries >= 2


# --------------------------------------------------------------------------
# Decisions
# --------------------------------------------------------------------------
@pytest.mark.parametrize("n_opp, expected", [(-3.0, +1), (-1.5, +1), (3.0, -1), (1.5, -1)])
def test_passes_on_the_side_with_room(n_opp, expected):
    s, n_ref, n_min, n_max = straight()
    opp = np.array([[40.0, n_opp, 40.0]])
    res = PassingSidePlanner().plan(s, n_ref, n_min, n_max, 0.0, opp)
    assert res.status == "optimal" and res.success
    assert res.sides[0] == expected
    assert res.max_slack == 0.0
    # the plan really clears the opponent where they overlap
    gap = opp[0, 0] + opp[0, 2] * CFG.node_dt * np.arange(N) - s
    over = np.abs(gap) < CFG.safe_lon
    assert over.any()
    assert np.all(expected * (res.d[over] - n_opp) >= CFG.safe_lat - 1e-6)


def test_side_by_side_opponents_share_one_decision():
    s, n_ref, n_min, n_max = straight()
    # an 8 m gap between them: threading would be feasible (|d| <= 0.25) ...
    opp = np.array([[50.0, -4.0, 40.0], [52.0, 4.0, 40.0]])
    res = PassingSidePlanner().plan(s, n_ref, n_min, n_max, 0.0, opp)
    assert res.success and res.n_binaries == 1
    assert res.sides[0] == res.sides[1] != 0
    # ... and without clustering the planner does thread between them (the check bites)
    free = PassingSidePlanner(MIQPConfig(cluster_gap=0.0)).plan(s, n_ref, n_min, n_max, 0.0, opp)
    assert free.n_binaries == 2
    assert free.sides[0] == +1 and free.sides[1] == -1


def test_alongside_lock_keeps_the_ego_between_two_cars_alongside():
    """Two cars alongside the ego, one on each side (the ego already threaded between them): the
    cluster rule alone makes it leave the gap through one of them; the alongside lock keeps it there."""
    s, n_ref, n_min, n_max = straight(v=30.0)
    opp = np.array([[1.0, -4.5, 30.0], [-1.0, 4.5, 30.0]])  # as fast as the ego: alongside for a while
    plain = PassingSidePlanner().plan(s, n_ref, n_min, n_max, 0.0, opp)
    assert plain.n_binaries == 1 and plain.sides[0] == plain.sides[1] and plain.max_slack > 2.0
    locked = PassingSidePlanner(MIQPConfig(alongside_gap=6.0)).plan(s, n_ref, n_min, n_max, 0.0, opp)
    assert locked.n_binaries == 2
    np.testing.assert_array_equal(locked.sides, [+1, -1])  # left of the right car, right of the left car
    assert locked.max_slack < 1e-6 and np.all(np.abs(locked.d) <= 0.75 + 1e-6)


@pytest.mark.parametrize("solver", ["daqp", "enumerate"])
def test_alongside_lock_is_hard_in_both_solver_routes(solver):
    """A car alongside on the ego's right, with room only on its right: without the lock the plan
    crosses to the free side; with it the ego stays left of the car (taking the slack)."""
    s, n_ref, n_min, n_max = straight(v=30.0)
    opp = np.array([[1.0, 2.0, 30.0]])  # alongside, 2 m left of the raceline
    ego_n = 4.0  # the ego is on its left, in a corridor that ends at 5 - margin
    free = PassingSidePlanner(MIQPConfig(solver=solver)).plan(s, n_ref, n_min, n_max, ego_n, opp)
    assert free.sides[0] == -1  # the cheap plan goes back to the raceline, through the car
    locked = PassingSidePlanner(MIQPConfig(solver=solver, alongside_gap=6.0)).plan(s, n_ref, n_min, n_max,
                                                                                    ego_n, opp)
    assert locked.success and locked.sides[0] == +1 and locked.max_slack > 0.0


def test_alongside_lock_keeps_the_side_of_a_car_alongside():
    s, n_ref, n_min, n_max = straight(v=20.0)
    opp = np.array([[0.5, 1.0, 20.0]])  # just left of the ego and alongside
    locked = PassingSidePlanner(MIQPConfig(alongside_gap=6.0)).plan(s, n_ref, n_min, n_max, -0.5, opp)
    assert locked.sides[0] == -1  # the ego is on its right and stays there
    opp_right = np.array([[0.5, -1.0, 20.0]])
    locked = PassingSidePlanner(MIQPConfig(alongside_gap=6.0)).plan(s, n_ref, n_min, n_max, 0.5, opp_right)
    assert locked.sides[0] == +1


@pytest.mark.parametrize("pair, free_side", [((0.0, 2.5), -1), ((0.0, -2.5), +1)])
def test_wide_blocking_pair_forces_the_free_side(pair, free_side):
    s, n_ref, n_min, n_max = straight()
    opp = np.array([[45.0, pair[0], 42.0], [47.0, pair[1], 42.0]])
    res = PassingSidePlanner().plan(s, n_ref, n_min, n_max, 0.0, opp)
    assert res.success and res.max_slack == 0.0
    np.testing.assert_array_equal(res.sides, [free_side, free_side])


# --------------------------------------------------------------------------
# Special cases, bounds, robustness
# --------------------------------------------------------------------------
@pytest.mark.parametrize("opponents", [np.zeros((0, 3)), np.array([[900.0, 0.0, 50.0]]),
                                       np.array([[-300.0, 0.0, 30.0]])])
def test_no_relevant_opponents_returns_the_clipped_reference(opponents):
    s, _, n_min, n_max = straight()
    n_ref = 6.0 * np.sin(s / 50.0)  # leaves the corridor in places
    res = PassingSidePlanner().plan(s, n_ref, n_min, n_max, 1.0, opponents)
    assert res.status == "no_opponents" and res.success and res.n_binaries == 0
    np.testing.assert_array_equal(res.d, np.clip(n_ref, n_min + 1.2, n_max - 1.2))
    np.testing.assert_array_equal(res.sides, np.zeros(len(opponents), dtype=int))
    np.testing.assert_array_equal(res.s, s)


def _free_optimum(n_ref, lo, hi, ego_n, cfg, d_prev=None):
    """The plan without side rows by an independent route: bounded linear least squares (scipy's BVLS) on
    sqrt(w_dev) (d - n_ref), sqrt(w_smooth) diff(d) and sqrt(w_prev) (d - d_prev), continuity at node 0."""
    from scipy.optimize import lsq_linear

    lo, hi = lo.copy(), hi.copy()
    e = float(np.clip(ego_n, lo[0], hi[0]))
    lo[0], hi[0] = max(lo[0], e - cfg.continuity), min(hi[0], e + cfg.continuity)
    blocks = [np.sqrt(cfg.w_dev) * np.eye(N), np.sqrt(cfg.w_smooth) * np.diff(np.eye(N), axis=0)]
    rhs = [np.sqrt(cfg.w_dev) * n_ref, np.zeros(N - 1)]
    if d_prev is not None:
        blocks.append(np.sqrt(cfg.w_prev) * np.eye(N))
        rhs.append(np.sqrt(cfg.w_prev) * d_prev)
    return lsq_linear(np.vstack(blocks), np.concatenate(rhs), bounds=(lo, hi), method="bvls", tol=1e-14).x


@pytest.mark.parametrize("solver", ["daqp", "enumerate"])
def test_the_smooth_free_plan_is_the_qp_without_side_constraints(solver):
    """``free_plan = "smooth"``: without a relevant opponent the plan is the problem above with no side row
    (continuity at node 0, the corridor, the deviation and smoothness costs, and with a previous plan its
    consistency term), where the default returns the clipped reference, a step from the ego's offset."""
    cfg = MIQPConfig(free_plan="smooth", solver=solver)
    s, _, n_min, n_max = straight()
    n_ref = 6.0 * np.sin(s / 50.0)  # leaves the corridor in places
    lo, hi = n_min + cfg.track_margin, n_max - cfg.track_margin
    planner = PassingSidePlanner(cfg)
    res = planner.plan(s, n_ref, n_min, n_max, 4.0, np.zeros((0, 3)))
    assert res.status == "optimal" and res.success and res.n_binaries == 0 and res.max_slack == 0.0
    np.testing.assert_allclose(res.d, _free_optimum(n_ref, lo, hi, 4.0, cfg), atol=1e-6)
    assert abs(res.d[0] - 4.0) <= cfg.continuity + 1e-9 and np.abs(np.diff(res.d)).max() < 0.5
    default = PassingSidePlanner().plan(s, n_ref, n_min, n_max, 4.0, np.zeros((0, 3)))
    assert default.status == "no_opponents" and abs(default.d[0] - 4.0) > 3.0
    # the next call, 3 m on, a car far ahead (not relevant): the consistency term with the previous plan
    again = planner.plan(s, n_ref, n_min, n_max, float(res.d[1]), np.array([[900.0, 0.0, 50.0]]), progress=3.0)
    d_prev = np.interp(s + 3.0, s, res.d)
    np.testing.assert_allclose(again.d, _free_optimum(n_ref, lo, hi, float(res.d[1]), cfg, d_prev), atol=1e-6)


def test_bounds_and_continuity_hold():
    rng = np.random.default_rng(11)
    for _ in range(20):
        s, n_ref, n_min, n_max, ego_n, opp = random_instance(rng, min_gap=5.0)
        res = PassingSidePlanner().plan(s, n_ref, n_min, n_max, ego_n, opp)
        assert res.success
        assert np.all(res.d >= n_min + CFG.track_margin - 1e-9)
        assert np.all(res.d <= n_max - CFG.track_margin + 1e-9)
        if res.status == "optimal":
            assert abs(res.d[0] - ego_n) <= CFG.continuity + 1e-9


def test_continuity_with_ego_outside_corridor_and_narrow_corridor():
    s, n_ref, n_min, n_max = straight()
    opp = np.array([[40.0, 0.0, 40.0]])
    res = PassingSidePlanner().plan(s, n_ref, n_min, n_max, 5.9, opp)  # beyond the margin
    edge = HALF_WIDTH - 1.2  # the ego offset is clipped to the corridor, then +- continuity
    assert res.success and edge - CFG.continuity - 1e-9 <= res.d[0] <= edge + 1e-9
    assert res.sides[0] == +1
    n_min2, n_max2 = n_min.copy(), n_max.copy()
    n_min2[30:40], n_max2[30:40] = 1.0, 3.0  # 2 m < two margins: collapses to its centre
    res = PassingSidePlanner().plan(s, n_ref, n_min2, n_max2, 0.0, opp)
    assert res.success
    np.testing.assert_allclose(res.d[30:40], 2.0, atol=1e-9)


def test_full_blockade_is_feasible_and_reports_slack():
    s, n_ref, n_min, n_max = straight()
    wall = np.array([[40.0, -4.0, 40.0], [40.5, 0.0, 40.0], [41.0, 4.0, 40.0]])
    for solver in ("daqp", "enumerate"):
        res = PassingSidePlanner(MIQPConfig(solver=solver)).plan(s, n_ref, n_min, n_max, 0.0, wall)
        assert res.success and res.status == "optimal"
        assert res.max_slack > 1.0 and res.slack_sum >= res.max_slack
        assert np.all(np.abs(res.d) <= HALF_WIDTH - 1.2 + 1e-9)
        assert np.all(res.sides != 0) and len(set(res.sides)) == 1
        assert np.isfinite(res.objective) and res.objective > CFG.w_slack


def test_overlap_between_sparse_nodes_is_covered():
    """Node spacing (12 m at 80 m/s vs a parked car) far exceeds a 2 m window."""
    cfg = MIQPConfig(safe_lon=2.0)
    s = 80.0 * cfg.node_dt * np.arange(N)
    opp = np.array([[30.0, -1.0, 0.0]])  # gaps 30, 18, 6, -6: the overlap falls between nodes
    res = PassingSidePlanner(cfg).plan(s, np.zeros(N), -6 * np.ones(N), 6 * np.ones(N), 0.0, opp)
    assert res.sides[0] == +1 and res.max_slack == 0.0
    # on the interpolated path, wherever the cars overlap, the clearance holds
    t = np.linspace(0.0, cfg.node_dt * (N - 1), 20001)
    s_t = np.interp(t, cfg.node_dt * np.arange(N), s)
    gap = opp[0, 0] + opp[0, 2] * t - s_t
    over = np.abs(gap) < cfg.safe_lon
    assert over.any()
    assert np.all(res.lateral_at(s_t[over]) >= opp[0, 1] + cfg.safe_lat - 1e-6)


def test_lateral_at_is_constant_beyond_the_ends():
    r = PlanResult(d=np.array([1.0, 2.0, 4.0]), s=np.array([0.0, 10.0, 20.0]),
                   sides=np.zeros(0, dtype=int), objective=0.0, status="optimal",
                   success=True, solve_time=0.0, n_binaries=0)
    np.testing.assert_allclose(r.lateral_at([-5.0, 5.0, 15.0, 99.0]), [1.0, 1.5, 3.0, 4.0])


def test_non_finite_input_falls_back_and_counts():
    s, n_ref, n_min, n_max = straight()
    planner = PassingSidePlanner()
    ok = planner.plan(s, n_ref, n_min, n_max, 0.0, np.array([[40.0, -3.0, 40.0]]))
    assert ok.success and planner.n_failures == 0
    bad = planner.plan(s, n_ref, n_min, n_max, 0.0, np.array([[np.nan, -3.0, 40.0]]), progress=2.0)
    assert bad.status == "fallback" and not bad.success and planner.n_failures == 1
    np.testing.assert_allclose(bad.d, ok.lateral_at(s + 2.0))  # previous plan, shifted
    assert np.isnan(bad.objective)
    planner.reset()
    assert planner.n_failures == 0


def test_solver_failure_falls_back_without_raising(monkeypatch):
    s, n_ref, n_min, n_max = straight()

    def broken(*args, **kwargs):
        raise RuntimeError("numerical trouble")

    monkeypatch.setattr(solvers_mod.daqp, "solve", broken)
    planner = PassingSidePlanner()
    n_ref = 8.0 * np.ones(N)
    res = planner.plan(s, n_ref, n_min, n_max, 0.0, np.array([[40.0, -3.0, 40.0]]))
    assert res.status == "fallback" and not res.success and planner.n_failures == 1
    np.testing.assert_allclose(res.d, HALF_WIDTH - 1.2)  # n_ref clipped into the corridor
    np.testing.assert_array_equal(res.sides, [0])


def test_invalid_shapes_raise():
    s, n_ref, n_min, n_max = straight()
    with pytest.raises(ValueError):
        PassingSidePlanner().plan(s[:-1], n_ref, n_min, n_max, 0.0, np.zeros((0, 3)))
    with pytest.raises(ValueError):
        PassingSidePlanner().plan(s, n_ref, n_min, n_max, 0.0, np.zeros((2, 2)))
