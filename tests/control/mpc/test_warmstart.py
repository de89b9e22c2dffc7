"""Initial guess: the shifted previous plan and the cold guess."""

import numpy as np

from sofar_env.control.barrier import BarrierParams
from sofar_env.control.mpc import MPCConfig
from sofar_env.control.mpc.warmstart import PlanShift, cold_guess
from sofar_env.vehicle import AV21


def test_shift_interpolates_in_time_and_reanchors():
    cfg = MPCConfig()
    t = cfg.time_grid()
    shift = PlanShift(cfg, AV21)
    # an accelerating plan: s = 40 t + t^2, v = 40 + 2 t, constant lateral offset, steering beyond its bound
    xs = np.column_stack([40.0 * t + t ** 2, np.full_like(t, 0.7), np.zeros_like(t), 40.0 + 2.0 * t,
                          np.full_like(t, 0.3)])
    us = np.column_stack([np.arange(cfg.horizon, dtype=float), np.zeros(cfg.horizon)])
    xg, ug = shift(xs, us)
    assert xg[0, 0] == 0.0
    s_plan = np.interp(t + cfg.control_dt, t, xs[:, 0])
    np.testing.assert_allclose(xg[:-2, 0], (s_plan - s_plan[0])[:-2], atol=1e-9)
    # exact for a linear v, also past the horizon (linear extrapolation)
    np.testing.assert_allclose(xg[:, 3], 40.0 + 2.0 * (t + cfg.control_dt), atol=1e-9)
    np.testing.assert_allclose(xg[:, 1], 0.7, rtol=1e-14)
    assert np.all(xg[:, 4] == AV21.steer_max)  # clipped to the steering bound
    # zero-order hold: the input planned at t_k + control_dt
    expected = [np.searchsorted(t, tk + cfg.control_dt + 1e-9, side="right") - 1 for tk in t[:-1]]
    np.testing.assert_array_equal(ug[:, 0], np.minimum(expected, cfg.horizon - 1))


def test_shift_keeps_the_speed_non_negative():
    cfg = MPCConfig()
    t = cfg.time_grid()
    xs = np.zeros((len(t), 5))
    xs[:, 3] = np.maximum(5.0 - 10.0 * t, 0.0) - 0.01 * t  # braking to a stop, slightly negative at the end
    xg, _ = PlanShift(cfg, AV21)(xs, np.zeros((cfg.horizon, 2)))
    assert xg[:, 3].min() >= 0.0 and xg[0, 3] > 0.0


def test_cold_guess_constant_speed_and_stays_behind_an_opponent_in_lane():
    t = MPCConfig().time_grid()
    bp = BarrierParams()
    x0 = np.array([0.0, 0.5, 0.0, 40.0, 0.0])
    xg, ug = cold_guess(x0, t, AV21, bp)
    np.testing.assert_allclose(xg[:, 0], 40.0 * t)
    assert np.all(xg[:, 1] == 0.5)
    np.testing.assert_allclose(xg[:, 3], 40.0, rtol=1e-12)
    np.testing.assert_allclose(ug, 0.0, atol=1e-9)
    # a slower car 20 m ahead in the lane: the guess stays a0 behind it, with feasible braking
    opp = np.array([[20.0, 0.0, 30.0], [5.0, 4.0, 30.0]])  # the second one is beside, not in the lane
    xg, ug = cold_guess(x0, t, AV21, bp, opp)
    gap = 20.0 + 30.0 * t - xg[:, 0]
    assert gap.min() >= bp.a0 - 1e-9
    assert np.all(np.diff(xg[:, 0]) >= 0.0) and np.all(ug[:, 0] >= AV21.a_min)


def test_the_compiled_anchor_and_bounds_are_the_numpy_form():
    from sofar_env.control.mpc.warmstart import _anchor_and_bound

    rng = np.random.default_rng(5)
    for trial in range(200):
        xg = rng.normal(size=(21, 5)) * [50.0, 3.0, 0.2, 30.0, 0.4]
        if trial % 4 == 0:  # zeros of both signs, values on the bounds, a nan
            xg[::3, 3] = -0.0
            xg[1::3, 3] = 0.0
            xg[::2, 4] = AV21.steer_max
            xg[1::4, 4] = -AV21.steer_max
            xg[5, 3] = np.nan
            xg[6, 4] = np.nan
        want = xg.copy()
        want[:, 0] -= want[0, 0]
        want[:, 4] = np.minimum(np.maximum(want[:, 4], -AV21.steer_max), AV21.steer_max)
        want[:, 3] = np.maximum(want[:, 3], 0.0)
        _anchor_and_bound(xg, AV21.steer_max)
        assert xg.tobytes() == want.tobytes()
