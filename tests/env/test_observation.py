"""The 12-value observation on a hand-built circuit whose geometry is known in closed form."""

import numpy as np
import pytest

from sofar_env.observation import GAP_RANGE, OBS_HIGH, OBS_LOW, OBS_NAMES, raw_observation, scale


class RingTrack:
    """A circular circuit of radius R: constant curvature 1/R, constant widths."""

    def __init__(self, radius=500.0, left=6.0, right=4.0):
        self.length = 2.0 * np.pi * radius
        self.kappa = 1.0 / radius
        self.left, self.right = left, right

    def gap(self, s_other, s):
        return (np.asarray(s_other, float) - s + self.length / 2.0) % self.length - self.length / 2.0

    def curvature(self, s):
        return np.full(np.shape(s), self.kappa)

    def width_left(self, s):
        return self.left

    def width_right(self, s):
        return self.right


def test_raw_values_on_a_ring():
    track = RingTrack()
    ego = np.array([100.0, 1.5, 0.02, 40.0, 0.1])                 # s, n, e, v, delta
    opponents = np.array([[160.0, -2.0, 30.0],                      # 60 m ahead
                          [90.0, 3.0, 45.0],                        # 10 m behind: inside the window, first
                          [400.0, 0.0, 20.0],                       # 300 m ahead: outside the window
                          [track.length - 50.0, 0.0, 20.0]])        # 150 m behind (wraps): outside
    raw = raw_observation(track, ego, opponents)
    expected = dict(ego_n=1.5, ego_v=40.0, steering=0.1, gap_1=-10.0, gap_2=60.0, n_1=3.0, n_2=-2.0,
                    dv_1=-5.0, dv_2=10.0, mean_curvature=track.kappa, width_left=6.0, width_right=4.0)
    np.testing.assert_allclose(raw, [expected[k] for k in OBS_NAMES])


def test_absent_opponents_read_as_far_away():
    track = RingTrack()
    raw = raw_observation(track, np.array([0.0, 0.0, 0.0, 20.0, 0.0]), np.zeros((0, 3)))
    got = dict(zip(OBS_NAMES, raw))
    assert got["gap_1"] == got["gap_2"] == GAP_RANGE[1]
    assert got["n_1"] == got["n_2"] == got["dv_1"] == got["dv_2"] == 0.0


def test_opponent_across_the_start_line_is_ahead():
    track = RingTrack()
    ego = np.array([track.length - 5.0, 0.0, 0.0, 30.0, 0.0])
    raw = raw_observation(track, ego, np.array([[15.0, 1.0, 25.0]]))
    assert dict(zip(OBS_NAMES, raw))["gap_1"] == pytest.approx(20.0)


def test_scale_maps_the_ranges_onto_unit_box():
    np.testing.assert_allclose(scale(OBS_LOW), -1.0)
    np.testing.assert_allclose(scale(OBS_HIGH), 1.0)
    np.testing.assert_allclose(scale((OBS_LOW + OBS_HIGH) / 2.0), 0.0, atol=1e-7)
    # beyond the range: clipped, never outside [-1, 1]
    np.testing.assert_allclose(scale(OBS_HIGH + 100.0), 1.0)
    assert scale(OBS_LOW).dtype == np.float32


def test_scaled_values_of_known_quantities():
    raw = np.array([7.5, 75.0, -0.125, 35.0, 200.0, 0.0, -15.0, 25.0, -50.0, 0.025, 7.5, 0.0])
    expected = [0.5, 0.5, -0.5, -0.5, 1.0, 0.0, -1.0, 0.5, -1.0, 0.5, 0.0, -1.0]
    np.testing.assert_allclose(scale(raw), expected, atol=1e-6)


def test_extended_values_on_a_ring():
    from sofar_env.control.barrier import BarrierParams, barrier
    from sofar_env.observation import extra_observation

    track = RingTrack()
    ego = np.array([100.0, 1.5, 0.02, 40.0, 0.1])
    opponents = np.array([[160.0, -2.0, 30.0, 0.8],      # 60 m ahead, moving left
                          [90.0, 3.0, 45.0, -1.2],       # 10 m behind: first
                          [400.0, 0.0, 20.0, 2.0]])      # outside the window
    bp = BarrierParams()
    raw = extra_observation(track, ego, opponents, bp)
    rel = np.array([[-10.0, 3.0, 45.0], [60.0, -2.0, 30.0], [300.0, 0.0, 20.0]])
    h = barrier(np.array([[0.0, 1.5, 0.02, 40.0, 0.1]]), rel, bp).min()
    np.testing.assert_allclose(raw, [-1.2, 0.8, 0.02, min(h, 9.0)])
    # without a rate column the rates read 0; without opponents the barrier reads far
    np.testing.assert_allclose(extra_observation(track, ego, opponents[:, :3], bp)[:2], 0.0)
    assert extra_observation(track, ego, np.zeros((0, 3)), bp)[3] == 9.0


def test_interactive_ids_observe_sixteen_values_and_paper_ids_twelve():
    import gymnasium as gym

    import sofar_env  # noqa: F401

    short = {"duration": 2.0}
    inter = gym.make("SOfAR-Monza-Interactive-v0", race=short)
    assert inter.observation_space.shape == (16,)
    obs, _ = inter.reset(seed=1)
    assert obs.shape == (16,) and inter.observation_space.contains(obs)
    assert gym.make("SOfAR-Monza-Interactive-v0", observation="paper", race=short).observation_space.shape == (12,)
    paper = gym.make("SOfAR-Monza-v0", race=short)
    assert paper.observation_space.shape == (12,)
    # the first twelve values are the paper layout of the same state
    flat = gym.make("SOfAR-Monza-Interactive-v0", observation="paper", race=short)
    assert np.array_equal(flat.reset(seed=1)[0], obs[:12])


@pytest.mark.parametrize("sensor", [False, True])
def test_the_extended_barrier_value_is_that_of_the_sensed_rows(sensor):
    """After a step the extended layout's barrier value is min_barrier of the rows the car senses, from its state now:
    without a sensor the decision's value (the same rows, reused), with one the sensor's rows (computed anew)."""
    import gymnasium as gym

    import sofar_env  # noqa: F401
    from sofar_env.control.barrier import min_barrier
    from sofar_env.observation import EXTENDED_HIGH, extra_observation

    race = {"duration": 3.0, "sensor": {"enabled": sensor}}
    env = gym.make("SOfAR-LagunaSeca-Interactive-v0", race=race, rho=0.3)
    env.reset(seed=4)
    core = env.unwrapped.core
    for _ in range(5):
        obs, *_ = env.step(np.array([0.3], np.float32))
        rows = core._sensed_rows[0]
        h = min_barrier(core.track, core.race.frenet[0], rows, core.measured_barrier)
        assert (rows is core._opponents[0]) is not sensor
        expected = extra_observation(core.track, core.race.frenet[0], rows, core.measured_barrier)
        assert expected[3] == min(h, EXTENDED_HIGH[15])
        assert np.array_equal(obs, core._observe(0))  # the reused value is the one computed afresh
