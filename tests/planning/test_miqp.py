"""Tests of the passing-side MIQP (sofar_env.planning.miqp)."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

import sofar_env.planning.miqp as miqp_mod
from sofar_env.planning import MIQPConfig, PassingSidePlanner, PlanResult

CFG = MIQPConfig()
N = CFG.nodes
HALF_WIDTH = 6.0  # m, a 12 m wide track centred on the raceline


def straight(v: float = 50.0, half_width: float = HALF_WIDTH):
    """Node arc lengths at constant speed, zero reference, symmetric edges."""
    s = v * CFG.node_dt * np.arange(N)
    return s, np.zeros(N), -half_width * np.ones(N), half_width * np.ones(N)


def random_instance(rng: np.random.Generator, min_gap: float = 10.0):
    v = rng.uniform(40.0, 60.0)
    t = CFG.node_dt * np.arange(N)
    s = v * t
    shift = rng.uniform(-2.0, 2.0)
    n_min = -HALF_WIDTH + shift + 0.5 * np.sin(s / 80.0)
    n_max = n_min + 12.0
    n_ref = 0.8 * np.sin(s / 60.0 + rng.uniform(0, 6))
    M = int(rng.integers(1, 5))
    opp = np.column_stack([rng.uniform(min_gap, 120.0, M), rng.uniform(-3.5, 3.5, M),
                           v * rng.uniform(0.75, 0.97, M)])
    return s, n_ref, n_min, n_max, float(rng.uniform(-1.0, 1.0)), opp


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


@pytest.mark.parametrize("pair, free_side", [((0.0, 2.5), -1), ((0.0, -2.5), +1)])
def test_wide_blocking_pair_forces_the_free_side(pair, free_side):
    s, n_ref, n_min, n_max = straight()
    opp = np.array([[45.0, pair[0], 42.0], [47.0, pair[1], 42.0]])
    res = PassingSidePlanner().plan(s, n_ref, n_min, n_max, 0.0, opp)
    assert res.success and res.max_slack == 0.0
    np.testing.assert_array_equal(res.sides, [free_side, free_side])


def test_hysteresis_keeps_the_previous_side():
    s, n_ref, n_min, n_max = straight()
    v = s[1] / CFG.node_dt
    # first call: opponent slightly right of centre -> left is cheaper
    opp1 = np.array([[80.0, -0.15, 42.0]])
    # 0.1 s later it sits slightly left of centre -> right would now be cheaper
    progress = 0.1 * v
    opp2 = np.array([[80.0 + (42.0 - v) * 0.1, 0.15, 42.0]])

    fresh = PassingSidePlanner().plan(s, n_ref, n_min, n_max, 0.0, opp2)
    assert fresh.sides[0] == -1

    for cfg, expected in ((MIQPConfig(), +1), (MIQPConfig(w_switch=0.0, w_prev=0.0), -1),
                          (MIQPConfig(w_prev=0.0), +1),
                          (MIQPConfig(solver="enumerate"), +1)):
        planner = PassingSidePlanner(cfg)
        first = planner.plan(s, n_ref, n_min, n_max, 0.0, opp1)
        assert first.sides[0] == +1
        second = planner.plan(s, n_ref, n_min, n_max, float(first.lateral_at(progress)), opp2,
                              progress=progress)
        assert second.sides[0] == expected, cfg


def test_hysteresis_follows_the_car_not_the_row():
    s, n_ref, n_min, n_max = straight()
    far = [150.0, 2.0, 45.0]  # irrelevant car listed first in the second call
    planner = PassingSidePlanner(MIQPConfig(w_prev=0.0))
    first = planner.plan(s, n_ref, n_min, n_max, 0.0, np.array([[80.0, -0.15, 42.0], far]))
    assert first.sides[0] == +1
    second = planner.plan(s, n_ref, n_min, n_max, 0.0, np.array([far, [79.0, 0.15, 42.0]]),
                          progress=5.0)
    assert second.sides[1] == +1  # a fresh planner would pass this one on the right
    fresh = PassingSidePlanner().plan(s, n_ref, n_min, n_max, 0.0, np.array([[79.0, 0.15, 42.0]]))
    assert fresh.sides[0] == -1


def test_hysteresis_ignores_a_respawned_opponent():
    s, n_ref, n_min, n_max = straight()
    planner = PassingSidePlanner(MIQPConfig(w_prev=0.0))
    first = planner.plan(s, n_ref, n_min, n_max, 0.0, np.array([[60.0, -0.15, 42.0]]))
    assert first.sides[0] == +1
    # same row index, but a different car 200 m further ahead: no inherited side
    second = planner.plan(s, n_ref, n_min, n_max, 0.0, np.array([[260.0, 0.15, 42.0]]),
                          progress=5.0)
    fresh = PassingSidePlanner(MIQPConfig(w_prev=0.0)).plan(
        s, n_ref, n_min, n_max, 0.0, np.array([[260.0, 0.15, 42.0]]))
    assert second.sides[0] == fresh.sides[0]


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

    monkeypatch.setattr(miqp_mod.daqp, "solve", broken)
    planner = PassingSidePlanner()
    n_ref = 8.0 * np.ones(N)
    res = planner.plan(s, n_ref, n_min, n_max, 0.0, np.array([[40.0, -3.0, 40.0]]))
    assert res.status == "fallback" and not res.success and planner.n_failures == 1
    np.testing.assert_allclose(res.d, HALF_WIDTH - 1.2)  # n_ref clipped into the corridor
    np.testing.assert_array_equal(res.sides, [0])


def test_invalid_configuration_and_shapes_raise():
    with pytest.raises(ValueError):
        MIQPConfig(solver="gurobi")
    with pytest.raises(ValueError):
        MIQPConfig(w_dev=0.0)
    s, n_ref, n_min, n_max = straight()
    with pytest.raises(ValueError):
        PassingSidePlanner().plan(s[:-1], n_ref, n_min, n_max, 0.0, np.zeros((0, 3)))
    with pytest.raises(ValueError):
        PassingSidePlanner().plan(s, n_ref, n_min, n_max, 0.0, np.zeros((2, 2)))


# --------------------------------------------------------------------------
# The vectorised clearance window against a direct (per-row, per-node) form.
# --------------------------------------------------------------------------
def reference_clearance(cfg: MIQPConfig, t: np.ndarray, s_nodes: np.ndarray, opp_s: np.ndarray) -> np.ndarray:
    """The clearance window of the module docstring, written out row by row."""
    L = cfg.safe_lon
    gap = opp_s - s_nodes[None, :]
    if cfg.closing_decel > 0.0:
        dv = -np.gradient(gap, t, axis=1)
        ext_ahead = np.maximum(dv, 0.0) ** 2 / (2.0 * cfg.closing_decel)
        ext_behind = np.maximum(-dv, 0.0) ** 2 / (2.0 * cfg.closing_decel)
    else:
        ext_ahead = ext_behind = np.zeros_like(gap)

    def required(g, e_ahead, e_behind):
        ext = np.where(g > 0.0, e_ahead, e_behind)
        a = np.abs(g)
        out = np.where(a < L, cfg.safe_lat, 0.0)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            r = (a - L) / ext
            cap = cfg.safe_lat * np.sqrt(np.clip(1.0 - r * r, 0.0, 1.0))
        return np.where((a >= L) & (ext > 0.0) & (a - L < ext), cap, out)

    w = required(gap, ext_ahead, ext_behind)
    a, b = gap[:, :-1], gap[:, 1:]
    g_near = np.where((a > 0.0) & (b > 0.0), np.minimum(a, b),
                      np.where((a < 0.0) & (b < 0.0), np.maximum(a, b), 0.0))
    seg = required(g_near, np.maximum(ext_ahead[:, :-1], ext_ahead[:, 1:]),
                   np.maximum(ext_behind[:, :-1], ext_behind[:, 1:]))
    w[:, :-1] = np.maximum(w[:, :-1], seg)
    w[:, 1:] = np.maximum(w[:, 1:], seg)
    stride = int(cfg.closing_stride)
    if stride > 1 and cfg.closing_decel > 0.0:
        box = np.abs(gap) < L
        out = w.copy()
        k = np.arange(w.shape[1])
        for i in range(w.shape[0]):
            bk = np.flatnonzero(box[i])
            if bk.size == 0:
                bk = np.array([int(np.argmax(w[i]))])
            dist = np.abs(k[:, None] - bk[None, :]).min(axis=1)
            drop = (w[i] > 0.0) & ~box[i] & (dist > 1) & ((dist - 1) % stride != 0)
            out[i, drop] = 0.0
        w = out
    return w


@pytest.mark.parametrize("closing_decel, stride", [(0.0, 3), (10.0, 1), (10.0, 3), (4.0, 2)])
def test_clearance_matches_the_direct_form_exactly(closing_decel, stride):
    cfg = MIQPConfig(closing_decel=closing_decel, closing_stride=stride)
    planner = PassingSidePlanner(cfg)
    rng = np.random.default_rng(3)
    t = CFG.node_dt * np.arange(N)
    for _ in range(200):
        v = rng.uniform(20.0, 70.0)
        s_nodes = v * t + 0.5 * rng.uniform(-4.0, 2.0) * t ** 2
        s_nodes = np.maximum.accumulate(np.maximum(s_nodes, 0.0))
        M = int(rng.integers(0, 6))
        s0 = rng.uniform(-40.0, 400.0, M)  # includes far opponents (skipped rows)
        vo = v * rng.uniform(0.3, 1.3, M)
        acc = rng.uniform(-5.0, 5.0, M)
        opp_s = s0[:, None] + vo[:, None] * t[None, :] + 0.5 * acc[:, None] * t[None, :] ** 2
        got = planner._clearance(s_nodes, opp_s)
        np.testing.assert_array_equal(got, reference_clearance(cfg, t, s_nodes, opp_s))


def test_time_gradient_matches_numpy():
    planner = PassingSidePlanner(MIQPConfig(closing_decel=10.0))
    f = np.random.default_rng(0).normal(size=(4, N)) * 50.0
    np.testing.assert_array_equal(planner._time_gradient(f), np.gradient(f, planner._t, axis=1))


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
