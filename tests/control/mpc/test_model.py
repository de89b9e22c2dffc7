"""The problem definition shared by both solvers: stage function, its linearisation, data, opponents."""

import numpy as np
import pytest

from sofar_env.control import barrier
from sofar_env.control.barrier import BarrierParams
from sofar_env.control.mpc import MPCConfig
from sofar_env.control.mpc.model import (linearisation_function, predict_opponents, relevant_slots, select_opponents,
                                         slack_weights, stage_function, stage_reference, track_limits,
                                         tracking_weights, variable_box)
from sofar_env.vehicle import AV21, frenet_rhs, lateral_acceleration, rk4_step

from .scenarios import make_stage


@pytest.fixture(scope="module")
def stage():
    return stage_function(AV21, BarrierParams(), 2, 1)


def _point(rng):
    x = np.array([0.0, rng.uniform(-3, 3), rng.uniform(-0.05, 0.05), rng.uniform(10, 70), rng.uniform(-0.2, 0.2)])
    u = np.array([rng.uniform(-10, 3), rng.uniform(-0.35, 0.35)])
    o = np.array([[rng.uniform(-30, 60), rng.uniform(-4, 4), rng.uniform(20, 60), rng.uniform(-0.5, 0.5)]
                  for _ in range(2)]).T
    return x, u, rng.uniform(-1 / 80, 1 / 80), rng.uniform(0.05, 0.1), o


def test_stage_function_is_the_vehicle_model_and_the_barrier(stage):
    rng = np.random.default_rng(0)
    for _ in range(20):
        x, u, kappa, dt, o = _point(rng)
        f, alat, h = (np.asarray(v).ravel() for v in stage(x, u, kappa, dt, o))
        f_ref = rk4_step(lambda xx, uu: frenet_rhs(xx, uu, kappa, AV21), list(x), list(u), dt, 1)
        np.testing.assert_allclose(f, f_ref, rtol=1e-13, atol=1e-12)
        assert alat[0] == pytest.approx(lateral_acceleration(x[3], x[4], AV21), rel=1e-13)
        np.testing.assert_allclose(h, barrier(x[None, :], o.T), rtol=1e-12)


def test_linearisation_is_the_jacobian_of_the_stage_function(stage):
    lin = linearisation_function(stage, "test_lin")
    rng = np.random.default_rng(1)
    eps = 1e-6
    for _ in range(5):
        x, u, kappa, dt, o = _point(rng)
        f, a, b, alat, dalat, h, dh = (np.asarray(v) for v in lin(x, u, kappa, dt, o))
        f0, alat0, h0 = (np.asarray(v) for v in stage(x, u, kappa, dt, o))
        np.testing.assert_array_equal(f, f0)  # the very same function values
        np.testing.assert_array_equal(alat, alat0)
        np.testing.assert_array_equal(h, h0)
        for j in range(5):  # central differences of f, alat and h in x_j
            d = np.zeros(5)
            d[j] = eps
            fp, ap, hp = (np.asarray(v).ravel() for v in stage(x + d, u, kappa, dt, o))
            fm, am, hm = (np.asarray(v).ravel() for v in stage(x - d, u, kappa, dt, o))
            np.testing.assert_allclose(a[:, j], (fp - fm) / (2 * eps), rtol=1e-5, atol=1e-6)
            if j in (3, 4):
                assert dalat[0, j - 3] == pytest.approx((ap - am)[0] / (2 * eps), rel=1e-5, abs=1e-6)
            if j in (0, 1, 3):
                np.testing.assert_allclose(dh[(0, 1, None, 2)[j]], (hp - hm) / (2 * eps), rtol=1e-5, atol=1e-6)
        for j in range(2):
            d = np.zeros(2)
            d[j] = eps
            fp = np.asarray(stage(x, u + d, kappa, dt, o)[0]).ravel()
            fm = np.asarray(stage(x, u - d, kappa, dt, o)[0]).ravel()
            np.testing.assert_allclose(b[:, j], (fp - fm) / (2 * eps), rtol=1e-5, atol=1e-7)


def test_cost_and_bound_data():
    cfg = MPCConfig(q=(0.0, 1.0, 2.0, 3.0, 4.0), r=(5.0, 6.0), track_margin=1.0)
    np.testing.assert_array_equal(tracking_weights(cfg), [5, 6, 0, 1, 2, 3, 4])
    stage = make_stage(v_ref=33.0, n_ref=1.5, half_width=5.0)
    arrays = np.array([stage.kappa, stage.n_ref, stage.v_ref, stage.n_min, stage.n_max])
    ref = stage_reference(arrays)
    assert ref.shape == (20, 7) and np.all(ref[:, 3] == 1.5) and np.all(ref[:, 5] == 33.0)
    assert np.count_nonzero(ref[:, [0, 1, 2, 4, 6]]) == 0
    lo, hi = track_limits(cfg, arrays)
    assert np.all(lo == -4.0) and np.all(hi == 4.0) and lo.shape == (20,)
    z1, z2 = slack_weights(cfg, False, True, 2)
    np.testing.assert_array_equal(z1, [cfg.track_slack[0]] + [cfg.barrier_slack[0]] * 2)
    np.testing.assert_array_equal(z2, [cfg.track_slack[1]] + [cfg.barrier_slack[1]] * 2)
    lo, hi = variable_box(AV21)
    np.testing.assert_array_equal(lo[[0, 1, 5, 6]], [AV21.a_min, -AV21.steer_rate_max, 0.0, -AV21.steer_max])
    np.testing.assert_array_equal(hi[[0, 1, 6]], [AV21.a_max, AV21.steer_rate_max, AV21.steer_max])
    assert np.all(np.isinf(lo[2:5])) and np.all(np.isinf(hi[2:6]))


def test_opponents_are_predicted_at_constant_velocity():
    rows = np.array([[10.0, 1.0, 30.0], [-5.0, -2.0, 45.0]])
    t = MPCConfig().time_grid()
    o = predict_opponents(rows, t)
    assert o.shape == (len(t), 2, 4)
    np.testing.assert_allclose(o[:, 1, 0], -5.0 + 45.0 * t)
    assert np.all(o[:, 0, 1] == 1.0) and np.all(o[:, 1, 2] == 45.0)
    assert np.all(o[:, :, 3] == 0.0)  # no lateral rate: course unknown
    # rows with a lateral rate: the sine of the course angle n_dot / v, below 1 m/s over 1 m/s, clipped
    o4 = predict_opponents(np.array([[10.0, 1.0, 30.0, 3.0], [0.0, 0.0, 0.5, -0.4], [0.0, 0.0, 0.2, 2.0]]), t)
    np.testing.assert_allclose(o4[0, :, 3], [0.1, -0.4, 1.0])
    np.testing.assert_allclose(o4[:, 0, 1], 1.0 + 3.0 * t)


def test_selection_keeps_the_window_and_the_most_relevant_opponents():
    cfg = MPCConfig(max_opponents=2)
    t = cfg.time_grid()
    xg = np.zeros((len(t), 5))
    xg[:, 0] = 40.0 * t
    xg[:, 3] = 40.0
    opp = np.array([[400.0, 0.0, 30.0],  # out of range ahead
                    [30.0, 0.0, 30.0],  # close, in lane: relevant
                    [80.0, 4.0, 38.0],
                    [-8.0, 3.5, 41.0],  # just behind, beside: relevant
                    [-60.0, 0.0, 50.0],  # out of range behind
                    [120.0, -4.0, 35.0]])
    sel = select_opponents(opp, xg, t, cfg)
    np.testing.assert_array_equal(sel, opp[[1, 3]])
    np.testing.assert_array_equal(select_opponents(opp, xg, t, MPCConfig()), opp[[1, 2, 3, 5]])
    assert len(select_opponents(opp, xg, t, MPCConfig(max_opponents=0))) == 0


def test_far_opponents_with_inactive_dcbf_get_no_rows():
    cfg = MPCConfig()  # opponent_h_keep 8, opponent_dcbf_keep 0.5
    k = np.arange(cfg.horizon + 1, dtype=float)
    h = np.column_stack([
        20.0 + 0.0 * k,  # far and steady: DCBF residual -0.3 * 20 = -6, left out
        90.0 - 4.0 * k,  # far (h >= 10) but closing fast: residual -0.3 h + 4 > -0.5 at the end, kept
        5.0 + 0.0 * k,  # near: kept
    ])
    np.testing.assert_array_equal(relevant_slots(h, 0.3, cfg), [1, 2])
    np.testing.assert_array_equal(relevant_slots(h, 0.3, MPCConfig(opponent_h_keep=np.inf)), [0, 1, 2])
    assert relevant_slots(h[:, :0], 0.3, cfg).size == 0


def test_the_compiled_prediction_is_the_numpy_form():
    from sofar_env.control.mpc.model import DUMMY_OPPONENT, predict_into

    def numpy_form(rows, t):
        out = np.empty((len(t), len(rows), 4))
        out[:, :, 0] = rows[:, 0] + rows[:, 2] * t[:, None]
        if rows.shape[1] == 4:
            out[:, :, 1] = rows[:, 1] + rows[:, 3] * t[:, None]
            out[:, :, 3] = np.clip(rows[:, 3] / np.maximum(rows[:, 2], 1.0), -1.0, 1.0)
        else:
            out[:, :, 1] = rows[:, 1]
            out[:, :, 3] = 0.0
        out[:, :, 2] = rows[:, 2]
        return out

    rng = np.random.default_rng(11)
    t = MPCConfig().time_grid()
    for trial in range(200):
        m = int(rng.integers(0, 5))
        rows = np.column_stack([rng.uniform(-50, 150, m), rng.uniform(-5, 5, m), rng.uniform(-1, 70, m),
                                rng.uniform(-20, 20, m)])
        if trial % 3 == 0:
            rows[:, 2] = rng.choice([0.0, -0.0, 1.0, 0.5], m)  # the speed floor and its ties
        if trial % 2:
            rows = rows[:, :3]
        want = numpy_form(rows, t)
        assert predict_opponents(rows, t).tobytes() == want.tobytes()
        o = np.full((len(t), 4, 4), 7.0)
        predict_into(rows, t, o, np.asarray(DUMMY_OPPONENT))
        assert o[:, :m].tobytes() == want.tobytes()
        assert np.all(o[:, m:] == DUMMY_OPPONENT)


def test_the_compiled_slot_choice_and_window_are_the_numpy_forms():
    rng = np.random.default_rng(5)
    cfg = MPCConfig()
    for case in range(200):
        m = int(rng.integers(0, 5))
        h = rng.uniform(-1.0, 30.0, (cfg.horizon + 1, m)) - rng.uniform(0.0, 3.0, m) * np.arange(cfg.horizon + 1)[:, None]
        if m and case % 4 == 0:
            h[rng.integers(cfg.horizon + 1), rng.integers(m)] = np.nan
        gamma = float(rng.choice([0.0, 0.05, 0.5, 1.0]))
        resid = (1.0 - gamma) * h[:-1] - h[1:]
        keep = (h.min(axis=0, initial=np.inf) < cfg.opponent_h_keep) | (
            resid.max(axis=0, initial=-np.inf) > -cfg.opponent_dcbf_keep)
        got = relevant_slots(h, gamma, cfg)
        np.testing.assert_array_equal(got, keep.nonzero()[0])
        assert got.dtype == np.intp
        opp = np.column_stack([rng.uniform(-80, 200, m), rng.uniform(-3, 3, m), rng.uniform(20, 60, m)])
        if m and case % 3 == 0:
            opp[0, 0] = np.nan
        t = cfg.time_grid()
        xg = np.column_stack([40.0 * t, np.zeros((len(t), 4))])
        mask = (opp[:, 0] >= -cfg.opponent_range_behind) & (opp[:, 0] <= cfg.opponent_range_ahead)
        if mask.sum() <= cfg.max_opponents:
            np.testing.assert_array_equal(select_opponents(opp, xg, t, cfg), opp[mask])
