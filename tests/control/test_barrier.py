"""Velocity-aware elliptic barrier: analytic values, numpy/CasADi agreement, closing speed."""

import numpy as np
import pytest

from sofar_env.control.barrier import BarrierParams, barrier, casadi_barrier, semi_axis_s, softplus

P = BarrierParams()


def _h(ds, dn, v=30.0, v_o=30.0, p=P):
    """h for an opponent at gap ds ahead, dn to the left, ego at the origin."""
    return float(barrier(np.array([0.0, 0.0, v]), np.array([ds, dn, v_o]), p))


def test_defaults_and_validation():
    assert (P.a0, P.b, P.a_brake) == (7.0, 2.7, 10.0)
    with pytest.raises(ValueError):
        BarrierParams(b=0.0)
    with pytest.raises(ValueError):
        BarrierParams(a0=float("nan"))


def test_zero_on_the_ellipse_at_equal_speed():
    # equal speeds: v_close = 0, a = a0 + softplus(0)^2 / (2 a_brake)
    a = P.a0 + (np.log(2.0) / P.sharpness) ** 2 / (2.0 * P.a_brake)
    for ang in np.linspace(0.0, 2.0 * np.pi, 13):
        assert _h(a * np.cos(ang), P.b * np.sin(ang)) == pytest.approx(0.0, abs=1e-12)
    assert _h(0.0, 0.0) == pytest.approx(-1.0)
    assert _h(0.0, P.b) == pytest.approx(0.0, abs=1e-12)


def test_collision_set_is_inside_the_zero_level_set():
    # centres (4.9 m, 1.9 m) apart: two 4.9 x 1.9 m rectangles touch at the corner
    for sx in (-1.0, 1.0):
        for sy in (-1.0, 1.0):
            assert _h(sx * 4.9, sy * 1.9) < 0.0
    # the whole Minkowski rectangle is unsafe
    ds, dn = np.meshgrid(np.linspace(-4.9, 4.9, 41), np.linspace(-1.9, 1.9, 17))
    opp = np.stack([ds, dn, np.full_like(ds, 30.0)], axis=-1)
    assert np.all(barrier(np.array([0.0, 0.0, 30.0]), opp) < 0.0)
    # analytic corner value with v_close = 0 (a exceeds a0 by the softplus offset, 1.5 mm)
    a = P.a0 + (np.log(2.0) / P.sharpness) ** 2 / (2.0 * P.a_brake)
    assert _h(4.9, 1.9) == pytest.approx((4.9 / a) ** 2 + (1.9 / 2.7) ** 2 - 1.0, abs=1e-12)
    assert _h(4.9, 1.9) == pytest.approx((4.9 / 7.0) ** 2 + (1.9 / 2.7) ** 2 - 1.0, abs=5e-4)
    # and a car fully beside (just outside b) is safe
    assert _h(0.0, 2.71) > 0.0


def test_semi_axis_grows_with_closing_speed_only_for_the_car_ahead():
    # ego faster by 20 m/s: ahead -> a ~ a0 + 400 / 20 = 27 m; behind -> a ~ a0
    a_ahead = semi_axis_s(30.0, 50.0, 30.0, P)
    a_behind = semi_axis_s(-30.0, 50.0, 30.0, P)
    assert a_ahead == pytest.approx(7.0 + 20.0 ** 2 / 20.0, rel=1e-3)
    assert a_behind == pytest.approx(7.0, abs=1e-3)
    # an opponent behind that is faster closes in: its ellipse grows
    assert semi_axis_s(-30.0, 30.0, 50.0, P) == pytest.approx(27.0, rel=1e-3)
    # so the same gap is less safe ahead than behind
    assert _h(20.0, 0.0, v=50.0, v_o=30.0) < 0.0 < _h(-20.0, 0.0, v=50.0, v_o=30.0)


def test_softplus_is_a_smooth_upper_bound_of_max():
    x = np.linspace(-50.0, 50.0, 2001)
    sp = softplus(x, 4.0)
    assert np.all(sp >= np.maximum(x, 0.0))
    assert np.max(sp - np.maximum(x, 0.0)) == pytest.approx(np.log(2.0) / 4.0, rel=1e-6)
    assert np.isfinite(softplus(np.array([1e6, -1e6]), 4.0)).all()


def test_numpy_and_casadi_agree_values_and_broadcast():
    f = casadi_barrier(P)
    rng = np.random.default_rng(0)
    xs = np.column_stack([rng.uniform(-5, 5, 50), rng.uniform(-4, 4, 50), rng.uniform(-0.2, 0.2, 50),
                          rng.uniform(0, 60, 50), rng.uniform(-0.2, 0.2, 50)])
    os_ = np.column_stack([rng.uniform(-40, 60, 50), rng.uniform(-4, 4, 50), rng.uniform(0, 60, 50)])
    num = barrier(xs, os_, P)
    sym = np.array([float(f(x, o)) for x, o in zip(xs, os_)])
    np.testing.assert_allclose(num, sym, rtol=1e-12, atol=1e-12)
    # (s, n, v) and full-state inputs agree; broadcasting gives one value per opponent
    np.testing.assert_allclose(barrier(xs[:, [0, 1, 3]], os_, P), num)
    assert barrier(xs[0], os_, P).shape == (50,)
    with pytest.raises(ValueError):
        barrier(np.zeros(4), os_, P)


def test_gradient_is_finite_at_equal_speed_and_zero_gap():
    import casadi as ca

    x = ca.SX.sym("x", 5)
    o = ca.SX.sym("o", 3)
    g = ca.Function("g", [x, o], [ca.gradient(casadi_barrier(P)(x, o), x)])
    for ds in (0.0, 5.0, -5.0):
        val = np.array(g([0.0, 0.0, 0.0, 30.0, 0.0], [ds, 0.5, 30.0])).ravel()
        assert np.all(np.isfinite(val))


def test_heading_extent_widens_the_lateral_semi_axis_with_the_egos_heading():
    """b + heading_extent (sqrt(sin^2 e + eps^2) - eps): zero on the widened ellipse's lateral vertex, the
    same in numpy, CasADi and min_barrier; without the option the heading is ignored."""
    import math

    from sofar_env.control.barrier import min_barrier

    wide = BarrierParams(heading_extent=2.45)
    e = 0.4
    b = 2.7 + 2.45 * (math.sqrt(math.sin(e) ** 2 + 1e-4) - 0.01)
    ego = np.array([0.0, 0.0, e, 30.0, 0.0])
    assert float(barrier(ego, np.array([0.0, b, 30.0]), wide)) == pytest.approx(0.0, abs=1e-12)
    assert float(barrier(ego, np.array([0.0, 3.0, 30.0]), wide)) < 0.0 < _h(0.0, 3.0)  # clear only when aligned
    aligned = ego.copy()
    aligned[2] = 0.0
    assert float(barrier(aligned, np.array([0.0, 2.7, 30.0]), wide)) == pytest.approx(0.0, abs=1e-12)
    assert float(barrier(ego, np.array([0.0, 2.7, 30.0]), P)) == pytest.approx(0.0, abs=1e-12)  # option off
    f = casadi_barrier(wide)
    opp = np.array([3.0, 2.9, 28.0])
    assert float(f(ego, opp)) == pytest.approx(float(barrier(ego, opp, wide)), abs=1e-12)

    class _Straight:
        @staticmethod
        def gap(a, b):
            return a - b

    assert min_barrier(_Straight(), ego, opp[None], wide) == pytest.approx(float(barrier(ego, opp, wide)), abs=1e-12)
    for bad in (-1.0, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="heading_extent"):
            BarrierParams(heading_extent=bad)


def _random_poses(seed: int, n: int = 100_000):
    """``n`` random relative poses of two AV-21 footprints on a straight track (the ego at the origin turned by up to
    1 rad, the opponent aligned within 8 m ahead or behind and 4.5 m to either side, both at 5 m/s): whether the
    footprints touch, the ego rows (s, n, e, v, delta) and the opponent rows (s, n, v)."""
    from sofar_env.configs.vehicle import AV21
    from sofar_env.geometry import footprint_corners, rectangles_intersect

    rng = np.random.default_rng(seed)
    e, ds, dn = rng.uniform(-1.0, 1.0, n), rng.uniform(-8.0, 8.0, n), rng.uniform(-4.5, 4.5, n)
    touch = rectangles_intersect(footprint_corners(np.zeros(n), np.zeros(n), e, AV21),
                                 footprint_corners(ds, dn, np.zeros(n), AV21))
    ego = np.stack([np.zeros(n), np.zeros(n), e, np.full(n, 5.0), np.zeros(n)], axis=-1)
    opp = np.stack([ds, dn, np.full(n, 5.0)], axis=-1)
    return touch, ego, opp


def test_heading_extent_certifies_no_contact_for_a_turned_ego():
    """The aligned ellipse certifies "no contact" only for aligned cars: an ego turned towards a car beside it
    touches it while h > 0 (by 0.9 at most). Widened by half the car's length times |sin e|, h < 0 wherever the
    two footprints touch, for any heading up to 1 rad (zero closing speed, a straight track, the opponent aligned);
    and at the paper world's protocol collision (Laguna Seca, a turn-in at 0.6 m/s beside a car at 2.5 m/s)."""
    from sofar_env.configs.vehicle import AV21
    from sofar_env.geometry import footprint_corners, rectangles_intersect

    wide = BarrierParams(heading_extent=2.45)
    touch, ego, opp = _random_poses(7)
    assert touch.sum() > 10_000
    assert np.all(barrier(ego, opp, wide)[touch] < 0.0)
    aligned = barrier(ego, opp, P)[touch]
    assert np.sum(aligned >= 0.0) > 1_000 and aligned.max() > 0.5  # the aligned ellipse misses turned contacts
    # the collision state: the opponent 0.19 m ahead and 2.71 m to the right, the ego turned 0.379 rad towards it
    ego = np.array([0.0, 0.0, -0.379, 0.62, 0.0])
    opp = np.array([0.19, -2.71, 2.48])
    assert rectangles_intersect(footprint_corners(0.0, 0.0, -0.379, AV21)[None],
                                footprint_corners(0.19, -2.71, 0.0, AV21)[None])[0]
    assert 0.0 < float(barrier(ego, opp, P)) < 0.02
    assert float(barrier(ego, opp, wide)) < -0.4


def test_toward_widens_only_by_the_turn_of_the_end_that_faces_the_opponent():
    """``heading_sides = "toward"``: with the opponent well ahead (10 m), a turn towards it widens the ellipse as
    ``"both"`` does and a turn away from it not at all; with the opponent well behind, the other way round (the
    rear end swings the other way); alongside, every turn widens it as ``"both"`` does. The same in numpy,
    CasADi and min_barrier."""
    from sofar_env.control.barrier import min_barrier

    both, toward = BarrierParams(heading_extent=2.45), BarrierParams(heading_extent=2.45, heading_sides="toward")

    def h(ds, dn, e, p):
        return float(barrier(np.array([0.0, 0.0, e, 30.0, 0.0]), np.array([ds, dn, 30.0]), p))

    for ds, dn in ((10.0, -2.5), (10.0, 2.5), (-10.0, -2.5), (-10.0, 2.5)):
        closer = 0.3 * np.sign(dn) * np.sign(ds)  # the facing end swings towards the opponent
        assert h(ds, dn, closer, toward) == pytest.approx(h(ds, dn, closer, both), abs=1e-2)
        assert h(ds, dn, -closer, toward) == pytest.approx(h(ds, dn, 0.0, P), abs=1e-2)
        assert h(ds, dn, -closer, toward) > h(ds, dn, -closer, both) + 0.05
    for e in (-0.3, 0.3):
        assert h(0.0, 2.5, e, toward) == pytest.approx(h(0.0, 2.5, e, both), abs=1e-12)
    assert h(10.0, 2.5, 0.0, toward) == pytest.approx(h(10.0, 2.5, 0.0, both), abs=1e-12)
    ego, opp = np.array([0.0, 0.4, 0.3, 12.0, 0.0]), np.array([6.6, -1.5, 2.0])
    assert float(casadi_barrier(toward)(ego, opp)) == pytest.approx(float(barrier(ego, opp, toward)), abs=1e-12)

    class _Straight:
        @staticmethod
        def gap(a, b):
            return a - b

    assert min_barrier(_Straight(), ego, opp[None], toward) == pytest.approx(float(barrier(ego, opp, toward)),
                                                                            abs=1e-12)
    with pytest.raises(ValueError, match="heading_sides"):
        BarrierParams(heading_extent=2.45, heading_sides="away")


def test_toward_still_certifies_no_contact_for_a_turned_ego():
    """Widened only by the turns that bring a car's end closer, h < 0 still holds wherever the two footprints
    touch, for any heading up to 1 rad (as for ``"both"``), while more of the states where they do not touch
    read h >= 0: a car behind another and turned away from it is not held back."""
    touch, ego, opp = _random_poses(11)
    toward = barrier(ego, opp, BarrierParams(heading_extent=2.45, heading_sides="toward"))
    both = barrier(ego, opp, BarrierParams(heading_extent=2.45))
    assert touch.sum() > 10_000 and np.all(toward[touch] < 0.0)
    assert np.all(toward >= both - 0.02)  # never much narrower than "both" (the smooth max dips by eps / 2)
    assert np.sum(toward >= 0.0) > 1.1 * np.sum(both >= 0.0)


def test_heading_extent_also_covers_the_opponents_course():
    """Rows (s, n, v, sin_course): the semi-axis widens by heading_extent |sin c|_eps for the opponent's
    course c as for the ego's heading; a course of 0 is the three-column row; without the option the course
    is ignored."""
    import math

    wide = BarrierParams(heading_extent=2.45)
    ego = np.array([0.0, 0.0, 0.2, 30.0, 0.0])
    c = 0.5
    b = 2.7 + 2.45 * (math.sqrt(math.sin(0.2) ** 2 + 1e-4) + math.sqrt(c ** 2 + 1e-4) - 0.02)
    assert float(barrier(ego, np.array([0.0, b, 30.0, c]), wide)) == pytest.approx(0.0, abs=1e-12)
    assert float(barrier(ego, np.array([0.0, -b, 30.0, -c]), wide)) == pytest.approx(0.0, abs=1e-12)
    row = np.array([2.0, 3.5, 31.0])
    assert float(barrier(ego, np.append(row, 0.0), wide)) == pytest.approx(float(barrier(ego, row, wide)), abs=1e-15)
    assert float(barrier(ego, np.append(row, c), wide)) < float(barrier(ego, row, wide))
    assert float(barrier(ego, np.append(row, c), P)) == float(barrier(ego, row, P))
    with pytest.raises(ValueError, match="opponents must end in 3 values"):
        barrier(ego, np.zeros(5), wide)


def _table_numpy(xs, opp, p):
    """The form barrier_table replaced: barrier() on broadcast rows, then numpy reductions."""
    h = barrier(xs[:, None, :], opp, p)
    return h, h.min(axis=0), float(h.min())


@pytest.mark.parametrize("heading,sides", [(0.0, "both"), (2.45, "both"), (2.45, "toward")])
def test_barrier_table_is_the_numpy_barrier_to_the_bit(heading, sides):
    from sofar_env.control.barrier import barrier_table

    p = BarrierParams(heading_extent=heading, heading_sides=sides)
    rng = np.random.default_rng(3)
    for trial in range(300):
        k, m = int(rng.integers(1, 23)), int(rng.integers(1, 9))
        xs = np.column_stack([rng.uniform(-5, 5, k), rng.uniform(-4, 4, k), rng.uniform(-0.4, 0.4, k),
                              rng.uniform(0, 80, k), rng.uniform(-0.25, 0.25, k)])
        opp = np.stack([rng.uniform(-60, 160, (k if trial % 2 else 1, m)), rng.uniform(-5, 5, (k if trial % 2 else 1, m)),
                        rng.uniform(0, 80, (k if trial % 2 else 1, m)), rng.uniform(-1, 1, (k if trial % 2 else 1, m))],
                       axis=-1)
        if trial % 5 == 0:  # ties and zeros: equal speeds, zero gaps, the ego at the opponent
            opp[..., 2] = xs[0, 3]
            opp[..., 0] = xs[0, 0]
        if trial % 3 == 0:
            opp = opp[..., :3]
        if trial % 7 == 0:  # a view, as rti passes opp[None, :, :3]
            opp = np.concatenate([opp, opp], axis=-1)[..., :3]
        got = barrier_table(xs, opp, p)
        want = _table_numpy(xs, opp, p)
        assert got[0].tobytes() == want[0].tobytes()
        assert got[1].tobytes() == want[1].tobytes()
        assert np.float64(got[2]).tobytes() == np.float64(want[2]).tobytes()
    # a nan propagates through both minima, as in numpy
    xs = np.array([[0.0, 0.0, 0.0, np.nan, 0.0], [0.0, 0.0, 0.0, 30.0, 0.0]])
    got, want = barrier_table(xs, np.array([[[10.0, 0.0, 20.0]]]), p), _table_numpy(xs, np.array([[[10.0, 0.0, 20.0]]]), p)
    assert np.isnan(got[1]).all() and np.isnan(got[2]) and np.isnan(want[2])


@pytest.mark.parametrize("heading,sides", [(0.0, "both"), (2.45, "both"), (2.45, "toward")])
def test_min_barrier_is_barrier_expr_on_floats(heading, sides):
    """The inlined min_barrier against the generic expression evaluated with math's functions, to the bit."""
    import math
    from types import SimpleNamespace

    from sofar_env.control.barrier import barrier_expr, min_barrier

    ops = SimpleNamespace(abs=abs, exp=math.exp, log1p=math.log1p, tanh=math.tanh, sin=math.sin, sqrt=math.sqrt)

    class Ring:
        def gap(self, s_o, s):
            return (s_o - s + 500.0) % 1000.0 - 500.0

    p = BarrierParams(heading_extent=heading, heading_sides=sides)
    rng = np.random.default_rng(9)
    for trial in range(300):
        ego = np.array([rng.uniform(0, 1000), rng.uniform(-5, 5), rng.uniform(-0.5, 0.5), rng.uniform(0, 80), 0.0])
        m = int(rng.integers(0, 6))
        opp = np.column_stack([rng.uniform(0, 1000, m), rng.uniform(-5, 5, m), rng.uniform(0, 80, m)])
        if trial % 4 == 0 and m:
            opp[0] = [ego[0], ego[1], ego[3]]  # on top of the ego, equal speeds
        want = math.inf
        for s_o, n_o, v_o in opp.tolist():
            want = min(want, barrier_expr(0.0, float(ego[1]), float(ego[3]), Ring().gap(s_o, float(ego[0])), n_o, v_o,
                                          p, ops, float(ego[2])))
        got = min_barrier(Ring(), ego, opp, p)
        assert np.float64(got).tobytes() == np.float64(want).tobytes()
