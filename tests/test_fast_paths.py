"""The hand-optimised copies in the hot loop give the very same numbers (bit for bit) as the plain forms:
the plant's RK4 step, the footprint corner list, the time derivative on a fixed grid
(``sofar_env._gradient.GridGradient``), the compiled interpolation kernel, the track's Python-float
paths and its scalar Frenet projection, the ego's node speeds and the MPC's finite-data check."""

import math

import numpy as np
import pytest

from sofar_env.geometry import footprint_corner_list, footprint_corners, footprint_radius
from sofar_env.vehicle import AV21, Plant, cartesian_rhs, rk4_step


def reference_plant_step(plant: Plant, x, u) -> np.ndarray:
    """The plant's step written with the generic RK4 of ``cartesian_rhs``."""
    p = plant.params
    a, dd = plant.clip_input(u)
    state = [float(v) for v in x]
    h = plant.dt / plant.substeps
    for _ in range(plant.substeps):
        state = rk4_step(lambda xx, uu: cartesian_rhs(xx, uu, p, math), state, (a, dd), h, 1)
        state[3] = max(state[3], 0.0)
        state[4] = min(max(state[4], -p.steer_max), p.steer_max)
    return np.array(state)


@pytest.mark.parametrize("substeps", [1, 4])
def test_plant_step_is_the_generic_rk4_of_the_model(substeps):
    plant = Plant(AV21, dt=0.1, substeps=substeps)
    rng = np.random.default_rng(0)
    for i in range(2000):
        x = np.array([rng.uniform(-500, 500), rng.uniform(-500, 500), rng.uniform(-7, 7),
                      rng.uniform(0, 90) if i % 5 else rng.uniform(0, 0.3), rng.uniform(-0.26, 0.26)])
        u = np.array([rng.uniform(-12, 4), rng.uniform(-0.5, 0.5)])
        np.testing.assert_array_equal(plant.step(x, u), reference_plant_step(plant, x, u))


def test_corner_list_matches_the_array_footprint():
    rng = np.random.default_rng(1)
    for _ in range(500):
        x, y, psi = rng.uniform(-1e3, 1e3), rng.uniform(-1e3, 1e3), rng.uniform(-7, 7)
        np.testing.assert_array_equal(np.array(footprint_corner_list(x, y, psi, AV21)),
                                      footprint_corners(x, y, psi, AV21))
    corners = footprint_corners(0.0, 0.0, 0.7, AV21)
    assert np.hypot(corners[:, 0], corners[:, 1]).max() <= footprint_radius(AV21) + 1e-12


@pytest.mark.parametrize("t", [np.arange(21) * 0.075,                                    # evenly spaced
                               np.concatenate([np.arange(10) * 0.075, 0.675 + np.arange(1, 12) * 0.15]),
                               np.array([0.0, 0.1]), np.array([0.0, 0.1, 0.35])])
def test_grid_gradient_is_numpy_gradient(t):
    from sofar_env._gradient import GridGradient

    grad = GridGradient(t)
    f = np.random.default_rng(5).normal(size=(4, t.size)) * 50.0
    np.testing.assert_array_equal(grad(f), np.gradient(f, t, axis=-1))
    np.testing.assert_array_equal(grad(f[0]), np.gradient(f[0], t))
    assert grad(np.zeros((0, t.size))).shape == (0, t.size)
    with pytest.raises(ValueError, match="samples"):
        grad(np.zeros(t.size + 1))


# ---------------------------------------------------------------- track, prediction, MPC checks


@pytest.fixture(scope="module")
def laguna():
    from sofar_env.tracks import Track

    return Track.load("LagunaSeca")


def _arc_lengths(track, n=400, seed=3):
    """Arc lengths inside, below, above and at the ends of [0, L), as Python floats."""
    rng = np.random.default_rng(seed)
    L = track.length
    special = [0.0, L, -L, 2.0 * L, float(np.nextafter(L, 0.0)), -1e-13, float(track.s[7]), -3.5 * L]
    return special + rng.uniform(-1.5 * L, 2.5 * L, n).tolist()


def test_compiled_interp_is_numpy_interp():
    from sofar_env._interp import interp

    rng = np.random.default_rng(2)
    xp = np.cumsum(rng.uniform(0.1, 2.0, 50))
    fp = rng.normal(size=50)
    x = rng.uniform(xp[0] - 5.0, xp[-1] + 5.0, (7, 9))
    np.testing.assert_array_equal(interp(x, xp, fp), np.interp(x, xp, fp))
    assert interp(float(x[0, 0]), xp, fp) == np.interp(float(x[0, 0]), xp, fp)


def test_track_float_paths_are_the_generic_paths(laguna):
    """speed / curvature / widths / wrap / gap at a Python float (the fast path) equal the same call at a
    numpy scalar and at a 0-d array (the generic scalar path), bit for bit; wrap and gap also equal the
    array path (the interpolated columns differ from numpy's interp formula in the last bit, by design:
    see ``Track._interp_scalar``)."""
    track = laguna
    values = _arc_lengths(track)
    arr = np.array(values)
    for name in ("speed", "curvature", "width_left", "width_right", "wrap"):
        method = getattr(track, name)
        fast = [method(v) for v in values]
        assert all(type(f) is float for f in fast)
        assert fast == [method(np.float64(v)) for v in values] == [method(np.array(v)) for v in values]
        if name == "wrap":
            np.testing.assert_array_equal(np.array(fast), method(arr))
        else:
            np.testing.assert_allclose(np.array(fast), method(arr), rtol=1e-14, atol=1e-14)
    other = np.random.default_rng(4).uniform(-track.length, 2.0 * track.length, arr.size)
    fast = [track.gap(a, b) for a, b in zip(values, other.tolist())]
    assert fast == [track._gap_scalar(float(a), float(b)) for a, b in zip(values, other)]
    np.testing.assert_array_equal(np.array(fast), track.gap(arr, other))


def _reference_newton_scalar(track, x, y, s, robust=False):
    """The scalar Newton projection written with the curve's own scalar evaluations."""
    from sofar_env.tracks.track import _NEWTON_MAX_ITER, _NEWTON_TOL

    curve = track._curve
    converged = False
    for _ in range(_NEWTON_MAX_ITER):
        px, py, dx, dy, ddx, ddy = curve.eval_scalar(s)
        ex, ey = px - x, py - y
        dd = dx * dx + dy * dy
        h = dd + ex * ddx + ey * ddy
        if h < 0.2 * dd:
            h = dd
        step = min(max(-(ex * dx + ey * dy) / h, -track._max_step), track._max_step)
        s = curve.wrap_scalar(s + step)
        if -_NEWTON_TOL < step < _NEWTON_TOL:
            converged = True
            break
    if not converged and not robust:
        return None
    px, py, dx, dy = curve.tangent_scalar(s)
    return s, (dx * (y - py) - dy * (x - px)) / math.hypot(dx, dy)


def test_scalar_projection_is_the_reference_newton(laguna):
    track = laguna
    rng = np.random.default_rng(6)
    s0 = rng.uniform(0.0, track.length, 300)
    x, y = track.to_cartesian(s0, rng.uniform(-12.0, 12.0, s0.size))
    hints = (s0 + rng.normal(0.0, 8.0, s0.size)) % track.length
    for xi, yi, hi in zip(x.tolist(), y.tolist(), hints.tolist()):
        for robust in (False, True):
            assert track._newton_scalar(xi, yi, hi, robust) == _reference_newton_scalar(track, xi, yi, hi, robust)


def test_ego_node_positions_follow_min_max_recurrence(laguna):
    from sofar_env.stack.prediction import ego_node_positions
    from sofar_env.vehicle import AV21

    node_t = np.arange(76) * 0.1
    for ego_s, ego_v, factor in ((10.0, 0.0, 1.0), (1500.0, 35.0, 0.9), (3000.0, 90.0, 1.0), (600.0, -1.0, 0.5)):
        got = ego_node_positions(laguna, ego_s, ego_v, node_t, 0.1, factor, AV21)
        v0 = max(ego_v, 0.0)  # the recurrence with Python's min and max, as written before
        s = v0 * node_t
        for _ in range(2):
            v = [v0]
            for vr in (factor * np.asarray(laguna.speed(ego_s + s), float))[:-1].tolist():
                v.append(min(max(vr, v[-1] + AV21.a_min * 0.1), v[-1] + AV21.a_max * 0.1))
            v = np.array(v)
            s = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * 0.1)])
        np.testing.assert_array_equal(got, s)


def test_speed_cap_gradient_follows_the_grid():
    """The followed cars' speeds are np.gradient along the grid given, also when the grid changes."""
    from sofar_env.stack.follow import PassOrFollow

    pof = PassOrFollow.__new__(PassOrFollow)  # only the gradient helper and its cache are exercised
    pof._time_gradient = None
    f = np.random.default_rng(8).normal(size=(3, 21)) * 30.0
    for t in (np.arange(21) * 0.075, np.concatenate([np.arange(10) * 0.075, 0.675 + np.arange(1, 12) * 0.15]),
              np.arange(21) * 0.075):
        np.testing.assert_array_equal(pof._gradient(t, f), np.gradient(f, t, axis=1))


def test_the_compiled_interpolation_is_numpys_to_the_bit():
    """interp_at (inside compiled kernels) against np.interp: random points, the knots themselves, both
    ends and beyond them, on a track's speed column and on random tables."""
    from sofar_env._interp import interp_at, wrap_at
    from sofar_env.tracks import Track

    track = Track.load("LagunaSeca")
    rng = np.random.default_rng(17)
    tables = [(track._knots, track._tables["v"][0]), (track._knots, track._tables["kappa"][0])]
    xp = np.cumsum(rng.uniform(0.01, 3.0, 50))
    tables.append((xp, rng.normal(size=50) * 40.0))
    for xp, fp in tables:
        x = np.concatenate([rng.uniform(xp[0] - 5.0, xp[-1] + 5.0, 3000), xp, [xp[0], xp[-1], -np.inf, np.inf]])
        got = np.array([interp_at(float(v), xp, fp) for v in x])
        np.testing.assert_array_equal(got, np.interp(x, xp, fp))
    L = track.length
    for s in np.concatenate([rng.uniform(-3 * L, 3 * L, 2000), [0.0, -0.0, L, -L, 2 * L, -1e-300, L - 1e-12]]):
        assert wrap_at(float(s), L) == track.wrap(float(s)) == float(track.wrap(np.array([s]))[0])


def test_the_compiled_pace_prediction_is_the_numpy_form():
    """OpponentPredictor (one compiled call) against its numpy expressions, bit for bit, across the
    lap seam, for stopped and reversing rows."""
    from sofar_env._interp import interp
    from sofar_env.stack.prediction import OpponentPredictor
    from sofar_env.tracks import Track

    track = Track.load("Monza")
    pred = OpponentPredictor(track)
    rng = np.random.default_rng(23)
    times = 0.15 * np.arange(40)
    for ego_s in (0.0, 17.0, track.length - 3.0, 0.5 * track.length):
        rows = np.column_stack([rng.uniform(-60.0, 200.0, 6), rng.uniform(-5, 5, 6), rng.uniform(-2.0, 90.0, 6)])
        rows[0, 2] = 0.0
        s_abs = np.asarray(track.wrap(ego_s + rows[:, 0]), float)
        rho = np.maximum(rows[:, 2], 0.0) / np.maximum(np.asarray(track.speed(s_abs), float), 0.1)
        t0 = interp(s_abs, pred._s, pred._t)
        s_pred = interp(t0[:, None] + rho[:, None] * times[None, :], pred._t, pred._s)
        np.testing.assert_array_equal(pred(ego_s, rows, times), rows[:, :1] + (s_pred - s_abs[:, None]))


def test_the_compiled_footprint_edges_are_the_numpy_form():
    """TrackEdges (one compiled call) against the narrowest widths over the footprint samples, computed with
    the track's array interpolation, bit for bit, across the lap seam."""
    from sofar_env.stack.edges import TrackEdges
    from sofar_env.tracks import Track

    track = Track.load("LagunaSeca")
    edges = TrackEdges(track, AV21)
    rng = np.random.default_rng(29)
    s_abs = np.concatenate([rng.uniform(-10.0, track.length + 10.0, 500), [0.0, track.length, -1.0]])
    pts = s_abs[:, None] + edges._offsets[None, :]
    wr = np.asarray(track.width_right(pts.ravel()), float).reshape(pts.shape).min(axis=1)
    wl = np.asarray(track.width_left(pts.ravel()), float).reshape(pts.shape).min(axis=1)
    n_min, n_max = edges(s_abs)
    np.testing.assert_array_equal(n_min, -wr)
    np.testing.assert_array_equal(n_max, wl)


def test_locate_does_not_depend_on_its_guess():
    """The interval found is searchsorted's, whatever the guess (a good one, a wrong one, out of range)."""
    from sofar_env._interp import locate

    rng = np.random.default_rng(31)
    xp = np.cumsum(rng.uniform(0.01, 2.0, 200))
    n = xp.size
    for x in np.concatenate([rng.uniform(xp[0] - 3.0, xp[-1] + 3.0, 2000), xp]):
        want = int(np.searchsorted(xp, x, side="right")) - 1
        want = min(want, n - 1)
        for guess in (-5, -1, 0, want - 1, want, want + 1, want + 3, n - 2, n - 1, n + 4, int(rng.integers(n))):
            assert locate(float(x), xp, guess) == want
    assert locate(float("nan"), xp, 3) == -2


def test_the_compiled_edge_envelope_is_the_numpy_form():
    """EdgeBand.envelope (one compiled call) against its numpy expressions, bit for bit: slow and fast cars,
    a band that narrows ahead, the lap seam, a zero lateral acceleration."""
    from sofar_env.opponents.lateral import _LOOKAHEAD, _LOOKAHEAD_TIME, EdgeBand
    from sofar_env.tracks import Track

    track = Track.load("Kentucky")
    band = EdgeBand(track, inner=1.5, half_width=0.95, half_length=2.45)

    def numpy_form(s, v, lateral_speed, lateral_accel):
        reach = max(_LOOKAHEAD_TIME * v, 50.0)
        d = reach * _LOOKAHEAD
        lo, hi = band.soft(s + d)
        t = d / max(v, 1e-3)
        u, a = lateral_speed, max(lateral_accel, 1e-9)
        t_ramp = u / a
        back = np.where(t < t_ramp, 0.5 * a * t * t, u * t - 0.5 * u * t_ramp)
        lo_e, hi_e = float(np.max(lo - back)), float(np.min(hi + back))
        if lo_e > hi_e:
            lo_e = hi_e = 0.5 * (lo_e + hi_e)
        return lo_e, hi_e

    rng = np.random.default_rng(37)
    cases = [(float(s), float(v), float(u), float(a)) for s, v, u, a in zip(
        rng.uniform(-50.0, track.length + 50.0, 400), rng.uniform(0.0, 90.0, 400),
        rng.uniform(0.0, 3.0, 400), rng.uniform(0.0, 6.0, 400))]
    cases += [(track.length - 1.0, 60.0, 1.5, 3.0), (0.0, 0.0, 1.5, 0.0), (10.0, 30.0, 0.0, 2.0)]
    for case in cases:
        assert band.envelope(*case) == numpy_form(*case)


def test_the_kernels_modulo_is_pythons():
    """wrap_mod (the stack kernels' x % L without fmod where it is exact) against Python's float modulo."""
    from sofar_env.stack._lookup import wrap_mod

    rng = np.random.default_rng(41)
    for L in (3588.419916, 1.0, 5793.1):
        xs = np.concatenate([rng.uniform(-3 * L, 3 * L, 3000), rng.uniform(0.0, 2.0 * L, 3000),
                             [0.0, -0.0, L, -L, 2 * L, np.nextafter(2 * L, 0.0), np.nextafter(L, 0.0),
                              np.nextafter(L, 3 * L), 5e-324, -5e-324, 1e300, -1e300, np.inf, -np.inf]])
        for x in xs.tolist():
            got, want = wrap_mod(x, L), x % L
            if math.isnan(want):  # inf % L
                assert math.isnan(got)
            else:
                assert got == want and math.copysign(1.0, got) == math.copysign(1.0, want)
        assert math.isnan(wrap_mod(float("nan"), L))


def test_the_footprint_edges_keep_numpys_bits_at_knots_seams_and_nan():
    """The edges' inlined look-up (uniform-spacing guess, slope table) at the knots themselves, next to
    them, across the seam and beyond two laps, and at nan, against the track's array interpolation."""
    from sofar_env.stack.edges import TrackEdges
    from sofar_env.tracks import Track

    for name in ("LagunaSeca", "Monza"):
        track = Track.load(name)
        edges = TrackEdges(track, AV21)
        knots = track.table("wl")[0]
        base = np.concatenate([knots[::7], np.nextafter(knots[::11], np.inf), np.nextafter(knots[1::13], -np.inf)])
        s_abs = np.concatenate([base - off for off in edges._offsets]
                               + [np.array([-3.0 * track.length, 2.5 * track.length, 2 * track.length, -1e-9])])
        pts = s_abs[:, None] + edges._offsets[None, :]
        wr = np.asarray(track.width_right(pts.ravel()), float).reshape(pts.shape).min(axis=1)
        wl = np.asarray(track.width_left(pts.ravel()), float).reshape(pts.shape).min(axis=1)
        n_min, n_max = edges(s_abs)
        np.testing.assert_array_equal(n_min, -wr)
        np.testing.assert_array_equal(n_max, wl)
        n_min, n_max = edges(np.array([np.nan, 10.0]))
        assert np.isnan(n_min[0]) and np.isnan(n_max[0]) and n_max[1] == edges(np.array([10.0]))[1][0]


def test_the_pace_prediction_keeps_numpys_bits_for_any_time_order():
    """The inlined travel-time look-up (the previous interval moved forward) for one time, decreasing and
    repeated times, a zero pace, and past the table's end, against the numpy form."""
    from sofar_env._interp import interp
    from sofar_env.stack.prediction import OpponentPredictor
    from sofar_env.tracks import Track

    track = Track.load("LagunaSeca")
    pred = OpponentPredictor(track)
    rng = np.random.default_rng(43)
    rows = np.column_stack([rng.uniform(-60.0, 200.0, 5), rng.uniform(-5, 5, 5), rng.uniform(0.0, 90.0, 5)])
    rows[0, 2] = 0.0
    for times in (np.array([1.3]), np.array([3.0, 1.0, 1.0, 2.0, 0.0]), 0.15 * np.arange(76),
                  np.array([0.0, 1e4, 0.5]), pred._t[100:140] - 3.0):
        for ego_s in (5.0, track.length - 30.0):
            s_abs = np.asarray(track.wrap(ego_s + rows[:, 0]), float)
            rho = np.maximum(rows[:, 2], 0.0) / np.maximum(np.asarray(track.speed(s_abs), float), 0.1)
            t0 = interp(s_abs, pred._s, pred._t)
            s_pred = interp(t0[:, None] + rho[:, None] * times[None, :], pred._t, pred._s)
            np.testing.assert_array_equal(pred(ego_s, rows, times), rows[:, :1] + (s_pred - s_abs[:, None]))


def test_ego_node_positions_keep_numpys_bits_across_the_seam(laguna):
    """The inlined speed-profile look-up of the ego's nodes across the lap seam and from a standstill at a
    knot, against the recurrence on the track's array interpolation."""
    from sofar_env.stack.prediction import ego_node_positions
    from sofar_env.vehicle import AV21

    node_t = np.arange(76) * 0.15
    knots = laguna.table("v")[0]
    for ego_s, ego_v in ((laguna.length - 40.0, 60.0), (float(knots[100]), 0.0), (-25.0, 30.0),
                         (2.0 * laguna.length - 1.0, 80.0)):
        got = ego_node_positions(laguna, ego_s, ego_v, node_t, 0.15, 1.0, AV21)
        s = ego_v * node_t
        for _ in range(2):
            v = [ego_v]
            for vr in np.asarray(laguna.speed(ego_s + s), float)[:-1].tolist():
                v.append(min(max(vr, v[-1] + AV21.a_min * 0.15), v[-1] + AV21.a_max * 0.15))
            v = np.array(v)
            s = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * 0.15)])
        np.testing.assert_array_equal(got, s)


def test_the_compiled_opponent_window_is_the_numpy_form(laguna):
    """relative_opponents (one compiled call) against the track's array gap, the window mask and argsort,
    bit for bit: across the seam, at the window's ends, nan rows, with and without the lateral-rate column,
    and ties (equal distances, which keep numpy's order)."""
    from sofar_env.stack.prediction import relative_opponents

    def numpy_form(ego_s, opp, behind, ahead):
        opp = np.asarray(opp, float)
        cols = opp.shape[-1] if opp.ndim == 2 and opp.shape[-1] == 4 else 3
        opp = opp.reshape(-1, cols)
        if opp.shape[0] == 0:
            return np.zeros((0, 3))
        gap = np.asarray(laguna.gap(opp[:, 0], ego_s), float).reshape(-1)
        keep = (gap >= -behind) & (gap <= ahead)
        rel = opp[keep]
        rel[:, 0] = gap[keep]
        return rel[np.argsort(np.abs(rel[:, 0]))]

    rng = np.random.default_rng(47)
    L = laguna.length
    for trial in range(400):
        M = int(rng.integers(0, 9))
        ego_s = float(rng.choice([rng.uniform(0, L), 1.0, L - 1.0, 0.0]))
        opp = np.column_stack([ego_s + rng.uniform(-80.0, 350.0, M), rng.uniform(-5, 5, M), rng.uniform(0, 90, M),
                               rng.uniform(-2, 2, M)])[:, :3 if trial % 2 else 4]
        if M >= 3 and trial % 5 == 0:
            opp[1, 0] = opp[0, 0]  # same place: a tie
            opp[2, 0] = 2.0 * ego_s - opp[0, 0]  # as far behind as the other is ahead
        if M >= 2 and trial % 7 == 0:
            opp[-1, 0] = np.nan
        if M >= 2 and trial % 11 == 0:
            opp[0, 0], opp[1, 0] = ego_s - 50.0, ego_s + 300.0  # the window's ends
        got = relative_opponents(laguna, ego_s, opp, 50.0, 300.0)
        want = numpy_form(ego_s, opp, 50.0, 300.0)
        assert got.shape == want.shape
        np.testing.assert_array_equal(got, want)
    assert relative_opponents(laguna, 0.0, np.zeros((0, 4)), 50.0, 300.0).shape == (0, 3)
    assert relative_opponents(laguna, 0.0, [10.0, 1.0, 30.0], 50.0, 300.0).shape == (1, 3)


def test_the_planners_compiled_glue_is_the_numpy_form():
    """The passing-side planner's corridor and finiteness test and pair slacks with the switch count (one
    compiled call each) against the numpy forms they replaced, bit for bit: crossing edges, nan and huge inputs,
    unknown previous sides (the per-opponent slack maximum: tests/planning/test_build.py)."""
    from sofar_env.planning.build import _corridor
    from sofar_env.planning.problem import SLACK_TOL, _slack_and_switch

    rng = np.random.default_rng(53)
    for trial in range(300):
        N, M = 76, int(rng.integers(0, 5))
        n_min, n_max = rng.uniform(-8, 1, N), rng.uniform(-1, 8, N)
        s_nodes, n_ref = np.cumsum(rng.uniform(0, 12, N)), rng.normal(size=N)
        opp, opp_s = rng.normal(size=(M, 3)) * 50, rng.normal(size=(M, N)) * 100
        ego_n, progress, m = float(rng.normal()), float(rng.uniform(0, 20)), 0.6
        bad = [n_min, n_max, s_nodes, n_ref] + ([opp, opp_s] if M else [])
        if trial % 4 == 1:
            bad[trial % len(bad)].flat[int(rng.integers(bad[trial % len(bad)].size))] = [np.nan, np.inf, 1e301][trial % 3]
        if trial % 9 == 0:
            progress = [np.nan, -np.inf, 2e300][trial % 3]
        lo, hi, bounded = _corridor(n_min, n_max, m, s_nodes, n_ref, opp, opp_s, ego_n, progress)
        lo_w, hi_w = n_min + m, n_max - m
        narrow = lo_w > hi_w
        mid = 0.5 * (n_min + n_max)
        lo_w, hi_w = np.where(narrow, mid, lo_w), np.where(narrow, mid, hi_w)
        np.testing.assert_array_equal(lo, lo_w)
        np.testing.assert_array_equal(hi, hi_w)
        finite = math.isfinite(s_nodes.sum() + n_ref.sum() + lo_w.sum() + hi_w.sum() + opp.sum() + opp_s.sum()
                               + ego_n + progress)
        assert (bounded or finite) == finite
        assert not bounded or finite

        P, C, R = int(rng.integers(0, 12)), int(rng.integers(1, 4)), max(M, 1)
        b = rng.integers(0, 2, C).astype(float)
        d = rng.normal(size=N) * 3
        pair_c, pair_k = rng.integers(0, C, P), rng.integers(0, N, P)
        pair_n, pair_w = rng.normal(size=P) * 3, rng.uniform(0.5, 3, P)
        rel_cluster, b_prev = rng.integers(0, C, R), rng.integers(-1, 2, R)
        got_xi, got_switch = _slack_and_switch(b, d, pair_c, pair_k, pair_n, pair_w, rel_cluster, b_prev)
        left = b[pair_c] > 0.5
        dk = d[pair_k]
        want_xi = np.where(left, pair_n + pair_w - dk, dk - (pair_n - pair_w))
        want_xi = np.where(want_xi > SLACK_TOL, want_xi, 0.0)
        known = b_prev >= 0
        np.testing.assert_array_equal(got_xi, want_xi)
        assert got_switch == float(((b[rel_cluster][known] - b_prev[known]) ** 2).sum())


def test_the_compiled_stay_behind_test_is_the_numpy_form():
    """PassOrFollow.can_stay_behind (one compiled call) against its numpy expressions, with and without
    follow_alongside: standing, reversing and nan ego speeds, nan predictions, the a0 boundary."""
    from sofar_env.stack.follow import _stay_behind
    from sofar_env.stack.prediction import braking_positions

    rng = np.random.default_rng(59)
    node_t = np.arange(76) * 0.15
    a0, decel = 7.0, 9.0
    for trial in range(400):
        M = int(rng.integers(0, 5))
        ego_v = float([rng.uniform(0, 90), 0.0, -3.0, np.nan, -0.0][trial % 5]) if trial % 3 == 0 else float(
            rng.uniform(0, 90))
        gap = rng.uniform(-10, 60, M)
        opp_s = gap[:, None] + rng.uniform(0, 60, M)[:, None] * node_t[None, :]
        if M and trial % 7 == 0:
            opp_s[0, int(rng.integers(76))] = np.nan
        if M > 1 and trial % 5 == 0:
            opp_s[1] = braking_positions(node_t, ego_v, decel) + a0  # the room exactly a0 throughout
        room = opp_s - braking_positions(node_t, ego_v, decel)[None, :]
        want_plain = room.min(axis=1) >= a0
        want_along = (room.min(axis=1) >= np.minimum(gap, a0) - 1e-6) & (room[:, -1] >= a0)
        np.testing.assert_array_equal(_stay_behind(node_t, ego_v, decel, gap, opp_s, a0, False), want_plain)
        np.testing.assert_array_equal(_stay_behind(node_t, ego_v, decel, gap, opp_s, a0, True), want_along)
