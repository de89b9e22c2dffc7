"""Prediction of the opponents' lateral motion from a sensed lateral rate (``StackConfig.lateral_prediction``)."""

import dataclasses

import numpy as np
import pytest

from sofar_env.control.barrier import barrier
from sofar_env.control.mpc.model import predict_opponents
from sofar_env.stack import OvertakingStack, StackConfig, stack_preset
from sofar_env.stack.prediction import lateral_motion


class _Straight:
    """A straight of constant width: 5 m to the left and 4 m to the right of the raceline."""

    length = 1000.0

    def wrap(self, s):
        return np.mod(s, self.length)

    def width_left(self, s):
        return np.full(np.shape(s), 5.0)

    def width_right(self, s):
        return np.full(np.shape(s), 4.0)

    def table(self, key):
        """(knots, values) of a sampled column, as :meth:`~sofar_env.tracks.Track.table` gives them."""
        return np.array([0.0, self.length]), np.full(2, {"wl": 5.0, "wr": 4.0}[key])


def test_lateral_motion_dead_band_and_edges():
    rows = np.array([
        [10.0, 0.0, 30.0, 0.2],    # inside the dead band: no motion
        [10.0, 0.0, 30.0, 1.3],    # 1.0 m/s after the dead band, 1.5 m in 1.5 s
        [10.0, 0.0, 30.0, -1.3],   # the same to the right
        [10.0, 3.0, 30.0, 2.3],    # stops 0.95 m inside the left edge (5 - 0.95 = 4.05)
        [10.0, -3.5, 30.0, -1.3],  # already closer to the right edge than the half width: stays
    ])
    n_end, rate = lateral_motion(_Straight(), 0.0, rows, 1.5, 0.3, 0.95)
    assert n_end == pytest.approx([0.0, 1.5, -1.5, 4.05, -3.5])
    assert rate == pytest.approx((n_end - rows[:, 1]) / 1.5)


def test_lateral_motion_is_its_numpy_form_to_the_bit():
    """The compiled form against the numpy expressions it replaced, on a real circuit, across the lap seam,
    with rates at and around the dead band, zeros of both signs, and cars outside the edges."""
    from sofar_env.tracks import Track

    track = Track.load("LagunaSeca")
    rng = np.random.default_rng(7)
    horizon, deadband, half_width = 1.5, 0.3, 0.95
    for trial in range(300):
        m = int(rng.integers(1, 7))
        rows = np.column_stack([rng.uniform(-60.0, 200.0, m), rng.uniform(-9.0, 9.0, m), rng.uniform(0.0, 60.0, m),
                                rng.choice([0.0, -0.0, 0.3, -0.3, 0.30000000000000004, 5.0], m) if trial % 3 == 0
                                else rng.normal(0.0, 1.5, m)])
        ego_s = float(rng.choice([0.0, track.length - 1e-9, float(rng.uniform(0.0, track.length))]))
        n, r = rows[:, 1], rows[:, 3]
        rate = np.sign(r) * np.maximum(np.abs(r) - deadband, 0.0)
        s_abs = track.wrap(ego_s + rows[:, 0])
        hi = np.maximum(np.asarray(track.width_left(s_abs), float) - half_width, n)
        lo = np.minimum(half_width - np.asarray(track.width_right(s_abs), float), n)
        ref = np.clip(n + rate * horizon, lo, hi)
        n_end, rate_out = lateral_motion(track, ego_s, rows, horizon, deadband, half_width)
        assert n_end.tobytes() == ref.tobytes()
        assert rate_out.tobytes() == ((ref - n) / horizon).tobytes()


def test_mpc_prediction_moves_a_car_across_at_its_rate():
    rows3 = np.array([[20.0, 1.0, 30.0]])
    rows4 = np.array([[20.0, 1.0, 30.0, -0.8]])
    t = np.array([0.0, 0.5, 1.5])
    p3, p4 = predict_opponents(rows3, t), predict_opponents(rows4, t)
    assert np.array_equal(p3[:, :, [0, 2]], p4[:, :, [0, 2]])
    assert p3[:, 0, 1] == pytest.approx([1.0, 1.0, 1.0])
    assert p4[:, 0, 1] == pytest.approx([1.0, 0.6, -0.2])
    # a zero rate predicts exactly what three columns do
    assert np.array_equal(predict_opponents(np.array([[20.0, 1.0, 30.0, 0.0]]), t), p3)


def test_a_car_moving_into_the_ego_line_is_avoided_earlier(tracks):
    """Kentucky straight, a slower car 25 m ahead and 2.5 m to the left moving right at 1.5 m/s:
    with the rate the MPC keeps the predicted path clear of where the car goes; without it, of
    where the car is."""
    track = tracks["Kentucky"]
    ego = np.array([100.0, 0.0, 0.0, 45.0, 0.0])
    opp = np.array([[125.0, 2.5, 38.0, -1.5]])

    def first_step(config, rows):
        return OvertakingStack(track, config).step(ego, rows, 0.5)

    with_rate = first_step(StackConfig(), opp)
    without = first_step(dataclasses.replace(StackConfig(), lateral_prediction=False), opp)
    blind = first_step(StackConfig(), opp[:, :3])  # three columns: no rate sensed
    # the planners saw the car where its move ends (1.8 m further right), or where it is
    assert with_rate.opponents_rel[0, 1] == pytest.approx(2.5 - 1.2 * 1.5)
    assert without.opponents_rel[0, 1] == pytest.approx(2.5)
    assert np.array_equal(without.u, blind.u)  # the option off ignores the fourth column
    # against the car's actual motion over the MPC's horizon, only the plan that knew the rate stays clear
    stack = OvertakingStack(track, StackConfig())
    truth = predict_opponents(np.array([[25.0, 2.5, 38.0, -1.5]]), stack._mpc_t)
    bp = StackConfig().mpc.barrier
    h_with = barrier(with_rate.mpc.x_pred[:, None, :], truth, bp).min()
    h_without = barrier(without.mpc.x_pred[:, None, :], truth, bp).min()
    assert h_with > 0.3 and h_without < 0.0
    # lateral_prediction_plan off: the planners see the car where it is, the MPC still gets its motion
    mpc_only = first_step(dataclasses.replace(StackConfig(), lateral_prediction_plan=False), opp)
    assert mpc_only.opponents_rel[0, 1] == pytest.approx(2.5)
    assert barrier(mpc_only.mpc.x_pred[:, None, :], truth, bp).min() > 0.3


def test_paper_preset_ignores_the_rate():
    assert not stack_preset("paper").lateral_prediction
    assert StackConfig().lateral_prediction


@pytest.mark.parametrize("bad", [dict(lateral_prediction_time=0.0), dict(lateral_prediction_time=float("nan")),
                                 dict(lateral_rate_deadband=-0.1), dict(lateral_rate_deadband=float("inf"))])
def test_bad_settings_are_refused(bad):
    with pytest.raises(ValueError, match=next(iter(bad))):
        StackConfig(**bad)
