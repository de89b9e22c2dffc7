"""MPC-DCBF real-time iteration: shapes and bounds, closed-loop DCBF, gamma, failures, left-out rows."""

import logging
import math

import numpy as np
import pytest

from sofar_env.control import MPCConfig, MPCDCBF, barrier
from sofar_env.vehicle import AV21

from .scenarios import N, make_stage, plant_step


def test_first_solve_shapes_bounds_and_predicted_s(cache_dir):
    mpc = MPCDCBF(MPCConfig(cache_dir=cache_dir))
    np.testing.assert_allclose(mpc.predicted_s(v0=40.0), 40.0 * MPCConfig().time_grid())
    res = mpc.solve(np.array([0.0, 0.5, 0.0, 40.0, 0.0]), make_stage(kappa=1 / 200), np.zeros((0, 3)), 0.5)
    assert res.success and res.status == "solved"
    assert res.x_pred.shape == (N + 1, 5) and res.u_pred.shape == (N, 2)
    assert res.barrier_min == math.inf and res.slack["barrier"] == 0.0
    assert AV21.a_min <= res.u[0] <= AV21.a_max and abs(res.u[1]) <= AV21.steer_rate_max
    assert np.all(np.abs(res.x_pred[1:, 4]) <= AV21.steer_max + 1e-6)
    s_next = mpc.predicted_s()
    assert s_next[0] == 0.0 and np.all(np.diff(s_next) > 0.0)
    # the warm start is the plan shifted by control_dt and re-anchored where the car will be then
    t = MPCConfig().time_grid()
    s_plan = np.interp(t + 0.1, t, res.x_pred[:, 0])
    np.testing.assert_allclose(s_next[:-2], (s_plan - s_plan[0])[:-2], atol=1e-9)


# --------------------------------------------------------------------------------------
# Closed loop on a straight road
# --------------------------------------------------------------------------------------


def closed_loop(gamma, cache_dir, opp0=(40.0, -1.5, 30.0), v=40.0, steps=60):
    """Ego at v in the middle of a 12 m road (n_ref = 0), a slower opponent ahead on a collision course."""
    cfg = MPCConfig(cache_dir=cache_dir)
    mpc = MPCDCBF(cfg)
    x = np.array([0.0, 0.0, 0.0, v, 0.0])
    o = np.array(opp0, dtype=float)
    stage = make_stage(v_ref=v, n_ref=0.0)
    log = []
    for _ in range(steps):
        x0 = x.copy()
        x0[0] = 0.0
        res = mpc.solve(x0, stage, np.array([[o[0] - x[0], o[1], o[2]]]), gamma)
        h0 = float(barrier(x, o, cfg.barrier))
        x = plant_step(x, res.u, cfg.control_dt)
        o = o + np.array([o[2] * cfg.control_dt, 0.0, 0.0])
        h1 = float(barrier(x, o, cfg.barrier))
        collide = abs(o[0] - x[0]) < AV21.length and abs(o[1] - x[1]) < AV21.width
        log.append((res, h0, h1, collide, math.hypot(o[0] - x[0], o[1] - x[1])))
    return log


@pytest.mark.parametrize("opp_n", [0.0, -1.5])
@pytest.mark.parametrize("gamma", [0.2, 0.6])
def test_closed_loop_dcbf_condition_and_no_collision(cache_dir, gamma, opp_n):
    log = closed_loop(gamma, cache_dir, opp0=(40.0, opp_n, 30.0))
    checked = 0
    for res, h0, h1, collide, _ in log:
        assert res.success
        assert not collide
        if res.barrier_slack_first < 1e-6:
            assert h1 >= (1.0 - gamma) * h0 - 1e-3
            checked += 1
    assert checked > 0.9 * len(log)
    # the barrier was actually engaged: the opponent got close in h
    assert min(h1 for _, _, h1, _, _ in log) < 1.0


def test_smaller_gamma_keeps_more_distance(cache_dir):
    cautious = closed_loop(0.05, cache_dir)
    bold = closed_loop(0.5, cache_dir)
    h_c = min(e[2] for e in cautious)
    h_b = min(e[2] for e in bold)
    d_c = min(e[4] for e in cautious)
    d_b = min(e[4] for e in bold)
    assert h_c > h_b + 0.1
    assert d_c > d_b + 1.0


def test_many_opponents_use_the_most_relevant_slots(cache_dir):
    mpc = MPCDCBF(MPCConfig(cache_dir=cache_dir, max_opponents=2))
    x0 = np.array([0.0, 0.0, 0.0, 40.0, 0.0])
    opp = np.array([[400.0, 0.0, 30.0],  # out of range
                    [30.0, 0.0, 30.0],  # close, in lane: relevant
                    [80.0, 4.0, 38.0],
                    [-8.0, 3.5, 41.0],  # just behind, beside: relevant
                    [120.0, -4.0, 35.0]])
    res = mpc.solve(x0, make_stage(), opp, 0.5)
    assert res.success and res.n_opponents == 2
    assert res.barrier_min == pytest.approx(float(barrier(x0, opp).min()))


# --------------------------------------------------------------------------------------
# Failures and malformed arguments
# --------------------------------------------------------------------------------------


def test_infeasible_state_falls_back_without_raising(cache_dir, caplog):
    mpc = MPCDCBF(MPCConfig(cache_dir=cache_dir))
    stage = make_stage()
    # steering far beyond its hard bound: delta_1 <= 0.25 cannot be reached in one step
    absurd = np.array([0.0, 50.0, 0.3, 40.0, 0.8])
    with caplog.at_level(logging.DEBUG, logger="sofar_env.control.mpc"):
        res = mpc.solve(absurd, stage, np.array([[20.0, 50.0, 30.0]]), 0.5)
    assert not res.success and res.status == "fallback_brake"
    assert res.u[0] == pytest.approx(AV21.a_min / 2) and res.u[1] == pytest.approx(-AV21.steer_rate_max)
    assert mpc.n_failures == 1
    assert any("failed" in r.message for r in caplog.records)
    # with a previous plan, the shifted plan's first control is used
    good = np.array([0.0, 0.0, 0.0, 40.0, 0.0])
    ok = mpc.solve(good, stage, np.zeros((0, 3)), 0.5)
    assert ok.success
    res = mpc.solve(absurd, stage, np.zeros((0, 3)), 0.5)
    assert res.status == "fallback_shift" and mpc.n_failures == 2
    np.testing.assert_allclose(res.u, np.clip(ok.u_pred[1], [AV21.a_min, -0.35], [AV21.a_max, 0.35]), atol=1e-9)
    # and it recovers
    assert mpc.solve(good, stage, np.zeros((0, 3)), 0.5).success
    mpc.reset()
    assert mpc.n_failures == 0


def test_non_finite_linearisation_falls_back(cache_dir, caplog):
    """At n = 1 / kappa the Frenet model is singular (s_dot = v cos / (1 - kappa n) = inf)."""
    mpc = MPCDCBF(MPCConfig(cache_dir=cache_dir))
    x0 = np.array([0.0, 2.0, 0.0, 40.0, 0.0])
    with caplog.at_level(logging.DEBUG, logger="sofar_env.control.mpc"):
        res = mpc.solve(x0, make_stage(kappa=0.5, n_ref=2.0), np.zeros((0, 3)), 0.5)
    assert not res.success and res.status == "fallback_brake" and np.all(np.isfinite(res.u))
    assert any("non-finite" in r.message for r in caplog.records)


def test_malformed_arguments_raise(cache_dir):
    mpc = MPCDCBF(MPCConfig(cache_dir=cache_dir))
    x0 = np.array([0.0, 0.0, 0.0, 40.0, 0.0])
    for args in ((x0, make_stage(), np.zeros((0, 3)), 1.5), (x0[:4], make_stage(), np.zeros((0, 3)), 0.5),
                 (x0, make_stage(n=N - 1), np.zeros((0, 3)), 0.5)):
        with pytest.raises(ValueError):
            mpc.solve(*args)
        with pytest.raises(ValueError):
            mpc.solve_converged(*args)
    assert mpc.n_failures == 0


# --------------------------------------------------------------------------------------
# Left-out rows and bounds (internal QP reduction) do not change the answer
# --------------------------------------------------------------------------------------


@pytest.mark.parametrize("scenario", ["lane_change", "track_edge", "slow", "opponents"])
def test_left_out_constraints_do_not_change_the_answer(cache_dir, scenario):
    """Leaving far-away rows and bounds out of the QP (and re-solving when the solution violates
    one) gives the same control as the QP with every row and bound, also when the rows bind.
    Tight QP tolerances, so that the comparison sees the formulation, not the solver's stopping point."""
    cfg = MPCConfig(cache_dir=cache_dir, qp_eps_abs=1e-11, qp_eps_rel=1e-12, qp_max_iter=500)
    default = MPCDCBF(cfg)
    full = MPCDCBF(cfg)
    full._rows_needed = lambda xbar, arrays: [True, True, True]
    reduced = MPCDCBF(cfg)  # always starts without them: every binding one is found by the check
    reduced._rows_needed = lambda xbar, arrays: [False, False, False]
    x = np.array([0.0, 0.0, 0.0, 40.0, 0.0])
    opp = np.zeros((0, 3))
    kappa = 0.0
    if scenario == "lane_change":  # a big lateral step at speed: the lateral-acceleration rows bind
        x[3] = 55.0
        stage = make_stage(v_ref=55.0, n_ref=4.5, kappa=1 / 300)
        kappa = 1 / 300
    elif scenario == "track_edge":  # the reference lies beyond the margined edge: the track rows bind
        stage = make_stage(v_ref=40.0, n_ref=5.5, half_width=6.0)
    elif scenario == "slow":  # hard braking to a stop: v >= 0 and a >= a_min bind
        x[3] = 6.0
        stage = make_stage(v_ref=0.0)
    else:
        stage = make_stage(v_ref=42.0)
        opp = np.array([[25.0, 0.3, 30.0], [-10.0, 3.5, 41.0]])
    worst = 0.0
    for _ in range(25):
        x0 = x.copy()
        x0[0] = 0.0
        for other in (full, reduced):
            other._xg = None if default._xg is None else default._xg.copy()
            other._ug = None if default._ug is None else default._ug.copy()
        res = default.solve(x0, stage, opp, 0.3)
        res_full = full.solve(x0, stage, opp, 0.3)
        res_red = reduced.solve(x0, stage, opp, 0.3)
        assert res.success and res_full.success and res_red.success
        worst = max(worst, float(np.abs(res.u - res_full.u).max()), float(np.abs(res_red.u - res_full.u).max()))
        x = plant_step(x, res.u, cfg.control_dt, kappa)
        opp = opp + np.column_stack([opp[:, 2] * cfg.control_dt, 0 * opp[:, 1:]]) if len(opp) else opp
    # 1e-5: at standstill (v ~ 1e-7, R_a = 0.01) even these tolerances leave a ~3e-6 spread between
    # solves of the very same QP; elsewhere the difference is below 1e-8
    assert worst < 1e-5, worst
    if scenario != "opponents":
        assert reduced.n_row_resolves > 0  # the check did find binding rows / bounds


def test_heading_extent_reaches_the_compiled_barrier(cache_dir):
    """BarrierParams.heading_extent: the compiled stage function evaluates the widened ellipse at the ego's
    heading (its barrier value at x0 is the numeric one with the heading), and the MPC solves with it."""
    from sofar_env.control.barrier import BarrierParams

    x0 = np.array([0.0, 0.0, 0.3, 30.0, 0.0])
    opp = np.array([[1.0, 3.2, 30.0]])
    stage = make_stage(v_ref=30.0, n_ref=0.0, half_width=8.0)
    values = {}
    for extent in (0.0, 2.45):
        cfg = MPCConfig(cache_dir=cache_dir, barrier=BarrierParams(heading_extent=extent))
        res = MPCDCBF(cfg).solve(x0.copy(), stage, opp, 0.3)
        assert res.status in ("solved", "fallback_brake")
        values[extent] = res.barrier_min
        assert res.barrier_min == pytest.approx(float(barrier(x0, opp[0], cfg.barrier)), abs=1e-9)
    assert values[0.0] > 0.0 > values[2.45]  # clear for aligned cars, inside the widened ellipse


def test_barrier_min_is_deferred_and_the_eager_value_to_the_bit(cache_dir):
    """MPCResult.barrier_min of opponents outside the MPC's window is evaluated on first access, from the solve's
    own copies: the value of the eager barrier_table call to the bit, whatever the caller does to its arrays after
    the solve; the result pickles and copies with it."""
    import copy
    import pickle

    from sofar_env.control.barrier import BarrierParams, barrier_table
    from sofar_env.control.mpc.rti import DeferredBarrierMin

    x0 = np.array([0.0, 0.4, 0.05, 40.0, 0.0])
    opp = np.array([[30.0, 1.0, 35.0, 0.1], [400.0, -2.0, 30.0, 0.0]])  # the second far outside the window
    for params in (BarrierParams(), BarrierParams(heading_extent=2.45)):
        cfg = MPCConfig(cache_dir=cache_dir, barrier=params)
        res = MPCDCBF(cfg).solve(x0.copy(), make_stage(v_ref=40.0, half_width=8.0), opp, 0.3)
        assert res.success and isinstance(res.h_now, DeferredBarrierMin)
        inside = float(res.h_now.partial)
        expected = min(inside, barrier_table(x0[None, :], opp[None, :, :3], params)[2])
        opp[:] = 0.0  # the caller reuses its buffer: the result keeps what the solve saw
        assert res.barrier_min == expected and inside >= expected
        assert pickle.loads(pickle.dumps(res)).barrier_min == expected == copy.deepcopy(res).barrier_min
        opp = np.array([[30.0, 1.0, 35.0, 0.1], [400.0, -2.0, 30.0, 0.0]])
    assert DeferredBarrierMin.of(x0, np.zeros((0, 3)), BarrierParams()) == math.inf


def test_the_input_clip_is_numpys(cache_dir):
    mpc = MPCDCBF(MPCConfig(cache_dir=cache_dir))
    lo, hi = mpc._box[0][:2], mpc._box[1][:2]
    rng = np.random.default_rng(8)
    for u in [*rng.normal(size=(200, 2)) * [8.0, 0.5], lo, hi, [-0.0, 0.0], [np.nan, 0.1], [np.inf, -np.inf]]:
        u = np.asarray(u, dtype=float)
        assert mpc._clip_input(u).tobytes() == np.clip(u, lo, hi).tobytes()
