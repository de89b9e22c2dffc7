"""The compiled pieces of the opponents' lateral step (:mod:`sofar_env.opponents.steering`): the line, the
tracker, the keep-clear bounds and the hard band give the numbers their formulas state, bit for bit where
the formula is written out here (scalar libm functions inside numba are the ones Python's ``math`` calls)."""

import bisect
import math

import numpy as np
import pytest

from sofar_env.opponents.config import DefenceConfig
from sofar_env.opponents.defence import ego_guarded
from sofar_env.opponents.lateral import EdgeBand, keep_clear, track_target
from sofar_env.opponents.lines import line_at
from sofar_env.tracks import Track


@pytest.fixture(scope="module")
def band():
    track = Track.load("LagunaSeca")
    return EdgeBand(track, inner=1.5, half_width=0.95, half_length=2.45)


def test_line_is_the_sum_of_its_two_sinusoids_to_the_bit():
    rng = np.random.default_rng(0)
    for s, off, a1, a2, w1, w2, p1, p2 in rng.uniform(-4000.0, 4000.0, size=(2000, 8)).tolist():
        x1, x2 = w1 * s + p1, w2 * s + p2
        n = off + a1 * math.sin(x1) + a2 * math.sin(x2)
        slope = a1 * w1 * math.cos(x1) + a2 * w2 * math.cos(x2)
        assert line_at(s, off, a1, a2, w1, w2, p1, p2) == (n, slope)


def test_tracker_holds_at_rest_on_its_target_and_starts_at_full_acceleration():
    assert track_target(1.0, 0.0, 1.0, 0.0, 1.5, 3.0, 0.04) == (1.0, 0.0)
    n, n_dot = track_target(0.0, 0.0, 2.0, 0.0, 1.5, 3.0, 0.04)
    assert n_dot == 3.0 * 0.04 and n == 0.5 * n_dot * 0.04


@pytest.mark.parametrize("seed", range(3))
def test_tracker_keeps_its_rate_and_acceleration_bounds(seed):
    rng = np.random.default_rng(seed)
    dt = 0.04
    for _ in range(3000):
        n, n_dot, target, rate = rng.uniform(-5.0, 5.0, 4).tolist()
        v_max, a_max = rng.uniform(0.1, 2.0, 2).tolist()
        lo, hi = sorted(rng.uniform(-6.0, 6.0, 2).tolist())
        n_new, nd_new = track_target(n, n_dot, target, rate, v_max, a_max, dt, lo, hi)
        assert abs(nd_new - n_dot) <= a_max * dt * (1 + 1e-12)
        assert abs(nd_new) <= max(abs(n_dot), v_max) * (1 + 1e-12)
        assert n_new == n + 0.5 * (n_dot + nd_new) * dt


def test_keep_clear_bounds_hold_the_car_and_share_the_room():
    lo, hi = keep_clear(3.0, 0.0, 2.0)  # left of the other car, 1 m of room
    assert (lo, hi) == (2.0, math.inf)
    assert keep_clear(3.0, 0.0, 2.0, share=0.5) == (2.5, math.inf)
    assert keep_clear(-3.0, 0.0, 2.0) == (-math.inf, -2.0)
    assert keep_clear(1.0, 0.0, 2.0) == (1.0, math.inf)  # already too close: may not close at all
    assert keep_clear(0.0, 0.0, 2.0, left=False) == (-math.inf, 0.0)


def test_ego_guard_window_grows_with_the_closing_speed():
    cfg = DefenceConfig(alongside_margin=1.0, guard_time=1.0)
    along = 4.9 + 1.0
    assert ego_guarded(along - 1e-9, 0.0, cfg, 4.9) and not ego_guarded(along, 0.0, cfg, 4.9)
    assert ego_guarded(along + 4.0, 5.0, cfg, 4.9) and not ego_guarded(-along - 4.0, 5.0, cfg, 4.9)
    assert ego_guarded(along + 4.0, 5.0, cfg, 4.9, 0.0) and not ego_guarded(along + 6.0, 5.0, cfg, 4.9)
    assert ego_guarded(along + 6.0, 5.0, cfg, 4.9, lead=1.0)


def test_hard_band_is_its_formula_on_the_sampled_widths(band):
    """The widths by bisection on the knots (the piece of the last knot <= s), the curvature the track's."""
    track = band.track
    knots, (wl, wr) = band._knots.tolist(), (w.tolist() for w in band._width_tables)
    rng = np.random.default_rng(3)
    values = rng.uniform(-track.length, 2.0 * track.length, 3000).tolist() + [0.0, track.length, -1e-13]
    for s in values:
        heading = float(rng.uniform(-0.3, 0.3))
        p = s % track.length
        k = min(max(bisect.bisect_right(knots, p) - 1, 0), len(knots) - 2)
        t = (p - knots[k]) / (knots[k + 1] - knots[k])
        w_l, w_r = wl[k] + t * (wl[k + 1] - wl[k]), wr[k] + t * (wr[k + 1] - wr[k])
        assert band.widths(s) == (w_l, w_r)
        bend = 0.5 * abs(track.curvature(s)) * band.half_length ** 2
        reach = band.half_width * abs(math.cos(heading)) + band.half_length * abs(math.sin(heading)) + bend + 0.05
        lo, hi = reach - w_r, w_l - reach
        assert band.hard(s, heading) == ((lo, hi) if lo <= hi else (0.5 * (lo + hi),) * 2)


def test_room_is_the_narrowest_soft_width_on_numpys_sample_points(band):
    """The band's room is the smallest ``hi - lo`` of :meth:`EdgeBand.soft` at ``s + np.linspace(0, d, k)``."""
    track = band.track
    rng = np.random.default_rng(4)
    cases = list(zip(rng.uniform(-track.length, 2.0 * track.length, 3000).tolist(),
                     rng.uniform(-50.0, 2500.0, 3000).tolist()))
    cases += [(0.0, 0.0), (track.length, 5.0), (-1e-13, 1e-300), (100.0, 1e-320), (3.0, 1999.9999)]
    for s, d in cases:
        k = min(math.ceil(max(d, 0.0) / 5.0) + 1, 400)
        lo, hi = band.soft(s + np.linspace(0.0, max(d, 0.0), k))
        assert band.room(s, d) == float(np.min(hi - lo))


def test_the_interactive_step_calls_its_kernels_with_arrays_only():
    """Python lists passed to a kernel are unboxed on every call (numba's deprecated reflected lists): the
    per-step kernels of the interactive world must only ever see arrays and scalars."""
    import gymnasium as gym

    from sofar_env.opponents import field, steering
    from sofar_env.stack import prediction

    env = gym.make("SOfAR-LagunaSeca-Interactive-v0", n_opponents=4)
    env.reset(seed=5)
    for _ in range(40):
        env.step(np.array([0.5], np.float32))
    env.close()
    from sofar_env import sensing

    for kernel in (field._advance_along, steering._steer, sensing._measure_rows, prediction._lateral_motion):
        assert kernel.signatures, kernel
        for signature in kernel.signatures:
            assert not any("list" in str(t) for t in signature), (kernel, signature)


@pytest.mark.parametrize("ds", [[1.0, 2.0], np.array([1, 2]), np.array([1.0, 2.0], dtype=np.float32)])
def test_limit_advances_refuses_advances_it_cannot_change_in_place(band, ds):
    from sofar_env.opponents import TrafficConfig
    from sofar_env.opponents.traffic import limit_advances

    kept = np.array(ds, copy=True)
    with pytest.raises(TypeError, match="float64 numpy array"):
        limit_advances(ds, [0.0, 30.0], [0.0, 0.0], [20.0, 20.0], np.array([[0.0, 30.0], [-30.0, 0.0]]), 0.1, band,
                       TrafficConfig(), 2.9, 5.9)
    assert np.array_equal(np.asarray(ds), kept)


def test_limit_advances_caps_a_car_closing_on_the_one_ahead_in_its_band(band):
    from sofar_env.opponents import TrafficConfig
    from sofar_env.opponents.traffic import limit_advances

    cfg = TrafficConfig()
    gap = cfg.follow_gap + 1.0  # car 0 is this far behind car 1, in the same band
    ds = np.array([3.0, 1.0])
    capped = limit_advances(ds, [0.0, gap], [0.0, 0.0], [30.0, 10.0], np.array([[0.0, gap], [-gap, 0.0]]), 0.1,
                            band, cfg, 2.9, 5.9)
    assert capped.tolist() == [True, False]
    assert ds.tolist() == [1.0 + (gap - cfg.follow_gap), 1.0]  # it keeps the follow gap after the step
