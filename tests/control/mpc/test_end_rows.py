"""The track rows on both ends of the car (``MPCConfig.track_rows = "ends"`` / ``"recoverable"``): the
offsets are those of the car's geometry (the recoverable envelope is the front end's largest offset on
the turn back at full lock, simulated), the QP's rows are the linearised offsets, the converged plan
keeps them inside the edges, and the RTI agrees with the IPOPT reference of the same problem."""

import numpy as np
import pytest

from sofar_env.control.mpc import MPCConfig, MPCDCBF
from sofar_env.control.mpc.ends import EndOffsets
from sofar_env.control.mpc.layout import N_FIXED, QPStructure
from sofar_env.control.mpc.linearisation import StageLinearisation
from sofar_env.vehicle import AV21, frenet_rhs, rk4_step

from .scenarios import make_stage

REACH = max(AV21.cg_to_front, AV21.cg_to_rear)


@pytest.mark.parametrize("value", ["Ends", "corners", "recover", "", None])
def test_unknown_track_rows_are_rejected(value):
    with pytest.raises(ValueError, match="track_rows"):
        MPCConfig(track_rows=value)


@pytest.mark.parametrize("lat", [True, False])
def test_end_rows_are_the_linearised_end_offsets(cache_dir, lat):
    cfg = MPCConfig(cache_dir=cache_dir, max_opponents=1, track_rows="ends")
    n_h = cfg.horizon
    t = cfg.time_grid()
    lin = StageLinearisation(cfg, AV21, np.diff(t))
    rng = np.random.default_rng(3)
    e_bar = rng.uniform(-0.6, 0.6, n_h)
    qs = QPStructure(cfg, 0, lat, True, lin.a_sparsity, lin.b_sparsity, lin.layout,
                     end_offsets=EndOffsets(AV21, recoverable=False))
    assert qs.ends and qs.nr == 2 * lat + 4
    flat = np.ones(lin.layout.size)  # the track rows take only the layout's constants from it
    flat[:lin.layout.n_const] = lin.layout.constants()
    qs.fill_matrices(flat, np.zeros(0, dtype=np.intp), 0.5)
    trk_lo, trk_hi = rng.uniform(-3.0, -1.0, n_h), rng.uniform(1.0, 3.0, n_h)
    qs.fill_ends(e_bar, trk_lo, trk_hi)
    z = rng.normal(size=qs.nz)
    zz = z.reshape(n_h, qs.nb)
    dn, de, sig = zz[:, 3], zz[:, 4], qs.slack_scale[int(lat)] * zz[:, N_FIXED + int(lat)]
    gz = (qs.G @ z).reshape(n_h, qs.nr)[:, qs.row_trk:qs.row_trk + 4]
    front, rear = dn + REACH * np.cos(e_bar) * de, dn - REACH * np.cos(e_bar) * de
    np.testing.assert_allclose(gz, np.column_stack([front - sig, front + sig, rear - sig, rear + sig]),
                               rtol=1e-12, atol=1e-12)
    hl = qs.hl_buf[:, qs.row_trk:qs.row_trk + 4]
    hu = qs.hu_buf[:, qs.row_trk:qs.row_trk + 4]
    swing = REACH * np.sin(e_bar)
    np.testing.assert_array_equal(hu[:, [0, 2]], np.column_stack([trk_hi - swing, trk_hi + swing]))
    np.testing.assert_array_equal(hl[:, [1, 3]], np.column_stack([trk_lo - swing, trk_lo + swing]))
    assert np.isneginf(hl[:, [0, 2]]).all() and np.isposinf(hu[:, [1, 3]]).all()
    # linearised at e_bar, the rows are exact there: the end offsets n +- l sin(e_bar) of a point on the edge
    assert np.allclose((trk_hi - swing) + REACH * np.sin(e_bar), trk_hi)


def test_plain_end_offsets_are_the_ends_of_the_car():
    e = np.linspace(-1.0, 1.0, 41)
    values, slopes = EndOffsets(AV21, recoverable=False)(e)
    s, c = REACH * np.sin(e), REACH * np.cos(e)
    np.testing.assert_array_equal(values, np.stack([s, s, -s, -s]))
    np.testing.assert_array_equal(slopes, np.stack([c, c, -c, -c]))


def _front_on_the_turn_back(e0: float) -> float:
    """The largest offset of the front end (from n = 0) of a car turned ``e0`` > 0 to the left that drives
    on at full right lock until it points along the track: the plant's model on a straight track."""
    x = [0.0, 0.0, e0, 5.0, -AV21.steer_max]
    front = REACH * np.sin(e0)
    while x[2] > 0.0:
        x = rk4_step(lambda xx, uu: frenet_rhs(xx, uu, 0.0, AV21), x, [0.0, 0.0], 0.002, 1)
        front = max(front, x[1] + REACH * np.sin(x[2]))
    return front


@pytest.mark.parametrize("e0", [0.1, 0.3, 0.35, 0.5, 0.75, 1.0])
def test_recoverable_front_offset_is_the_largest_on_the_turn_back(e0):
    ends = EndOffsets(AV21, recoverable=True)
    values, _ = ends(np.array([e0, -e0]))
    assert values[0, 0] == pytest.approx(_front_on_the_turn_back(e0), abs=1e-3)
    assert values[1, 1] == -values[0, 0]  # mirrored for the right edge
    assert values[2, 0] == -REACH * np.sin(e0)  # the rear end needs no room: it swings in on the turn back
    if e0 <= ends.e_star:
        assert values[0, 0] == REACH * np.sin(e0)


def test_recoverable_offsets_are_smooth_and_their_slopes_are_the_derivatives():
    ends = EndOffsets(AV21, recoverable=True)
    assert 0.3 < ends.e_star < 0.32  # the AV-21: 0.31 rad
    e = np.concatenate([np.linspace(-1.2, 1.2, 97), [ends.e_star, -ends.e_star]])
    h = 1e-6
    values, slopes = ends(e)
    fd = (ends(e + h)[0] - ends(e - h)[0]) / (2 * h)
    np.testing.assert_allclose(slopes, fd, atol=1e-5)
    left, right = ends(np.array([ends.e_star - 1e-9]))[0], ends(np.array([ends.e_star + 1e-9]))[0]
    np.testing.assert_allclose(left, right, atol=1e-8)


def _pulled_towards_the_edge():
    """At 20 m/s, 3 m left of the centre line and turned 0.2 rad to the left, with a lateral reference
    beyond the left bound (6 m edge - 1.2 m margin = 4.8 m): the plan runs against the bound."""
    return np.array([0.0, 3.0, 0.2, 20.0, 0.0]), make_stage(v_ref=20.0, n_ref=5.5, half_width=6.0)


def _converged(track_rows, cache_dir, solver="solve"):
    cfg = MPCConfig(control_dt=0.0, cache_dir=cache_dir, track_rows=track_rows)
    mpc = MPCDCBF(cfg)
    x0, stage = _pulled_towards_the_edge()
    for _ in range(12 if solver == "solve" else 1):
        res = getattr(mpc, solver)(x0, stage, np.zeros((0, 3)), 0.5)
        assert res.success
    return cfg, res


def test_converged_plan_keeps_both_ends_inside_the_edges(cache_dir):
    cfg, ends = _converged("ends", cache_dir)
    bound = 6.0 - cfg.track_margin
    x = ends.x_pred[1:]
    assert (x[:, 1] + REACH * np.abs(np.sin(x[:, 2]))).max() <= bound + 1e-6 and ends.slack["track"] < 1e-6
    # bounding the reference point only, the plan reaches the bound with the car still turned: its front
    # end is more than 0.1 m beyond it
    _, ref = _converged("reference", cache_dir)
    x = ref.x_pred[1:]
    assert x[:, 1].max() <= bound + 1e-6
    assert (x[:, 1] + REACH * np.abs(np.sin(x[:, 2]))).max() > bound + 0.1


def test_rti_matches_the_ipopt_reference_with_end_rows(cache_dir):
    _, rti = _converged("ends", cache_dir)
    cfg, ref = _converged("ends", cache_dir, solver="solve_converged")
    np.testing.assert_allclose(rti.x_pred[:, 1], ref.x_pred[:, 1], atol=0.02)
    np.testing.assert_allclose(rti.x_pred[:, 2], ref.x_pred[:, 2], atol=0.01)
    x = ref.x_pred[1:]  # the reference bounds the ends too
    assert (x[:, 1] + REACH * np.abs(np.sin(x[:, 2]))).max() <= 6.0 - cfg.track_margin + 1e-6


def _rti_and_reference(track_rows, cache_dir, x0, stage, atol):
    """15 RTI iterations at one state, then IPOPT from the RTI's solution: it converges to the same point (the
    problem is non-convex: from a cold guess IPOPT may find another local optimum). ``(config, rti, reference)``."""
    cfg = MPCConfig(control_dt=0.0, cache_dir=cache_dir, track_rows=track_rows)
    rti = MPCDCBF(cfg)
    for _ in range(15):
        res = rti.solve(x0, stage, np.zeros((0, 3)), 0.5)
        assert res.success
    ref = rti.solve_converged(x0, stage, np.zeros((0, 3)), 0.5)
    assert ref.success
    np.testing.assert_allclose(res.x_pred, ref.x_pred, atol=atol)
    return cfg, res, ref


@pytest.mark.parametrize("track_rows", ["ends", "recoverable"])
def test_turned_beyond_recovery_the_rti_matches_the_ipopt_reference(cache_dir, track_rows):
    """At 6 m/s, 3 m left and turned 0.5 rad (beyond e* = 0.31) towards the left edge, pulled further left:
    no plan keeps the front end inside; both solvers brake and steer away with the same slacks."""
    x0, stage = np.array([0.0, 3.0, 0.5, 6.0, 0.0]), make_stage(v_ref=10.0, n_ref=5.5, half_width=6.0)
    cfg, res, ref = _rti_and_reference(track_rows, cache_dir, x0, stage, atol=1e-6)
    assert res.slack["track"] == pytest.approx(ref.slack["track"], abs=1e-6) and res.slack["track"] > 0.1
    assert res.u[0] == pytest.approx(AV21.a_min) and res.u[1] < 0.0  # full braking, steering away from the edge
    values, _ = EndOffsets(AV21, recoverable=track_rows == "recoverable")(res.x_pred[1:, 2])
    assert (res.x_pred[1:, 1] + values[0]).max() == pytest.approx(6.0 - cfg.track_margin + res.slack["track"],
                                                                   abs=1e-3)


def _front_on_the_turn_back_in_a_corner(e0: float, kappa: float) -> float:
    """The largest offset of the front end (from n = 0) of a car turned ``e0`` > 0 to the left, driving on at full
    right lock through a corner of constant curvature ``kappa`` (< 0: a right-hand corner, which turns the track
    away from the car) until it points along the track: the plant's Frenet model."""
    x = [0.0, 0.0, e0, 3.0, -AV21.steer_max]
    front = REACH * np.sin(e0)
    for _ in range(200_000):
        if x[2] <= 0.0:
            return front
        x = rk4_step(lambda xx, uu: frenet_rhs(xx, uu, kappa, AV21), x, [0.0, 0.0], 0.002, 1)
        front = max(front, x[1] + REACH * np.sin(x[2]))
    raise AssertionError("the car did not turn back")


@pytest.mark.parametrize("e0", [0.2, 0.5, 0.75, 1.0])
@pytest.mark.parametrize("radius", [100.0, 40.0, 22.0])
def test_curved_envelope_keeps_the_room_a_corner_takes_to_turn_back_in(e0, radius):
    """``"recoverable-curved"``: in a corner that turns the track away from the car (turned left, a right-hand
    corner) the front end goes further out on the turn back than on a straight; the rows keep at least that
    room (conservative: they take the track's direction to turn at the car's speed), and on a straight or in a
    corner that turns towards the car they are the straight envelope's."""
    curved, straight = EndOffsets(AV21, recoverable=True, curved=True), EndOffsets(AV21, recoverable=True)
    e = np.array([e0, -e0])
    simulated = _front_on_the_turn_back_in_a_corner(e0, -1.0 / radius)
    values, _ = curved(e, np.array([-1.0 / radius, 1.0 / radius]))  # both cars turned towards the outside edge
    assert values[0, 0] >= simulated - 1e-3
    assert values[1, 1] == pytest.approx(-values[0, 0])  # mirrored for the right edge of a left-hand corner
    assert values[0, 0] <= 2.5 * simulated + 0.5  # and not far beyond it
    on_straight, _ = straight(e)
    assert values[0, 0] >= on_straight[0, 0] and (e0 <= curved.e_star or values[0, 0] > on_straight[0, 0])
    np.testing.assert_array_equal(curved(e, np.zeros(2))[0], on_straight)
    np.testing.assert_array_equal(curved(e, np.array([1.0 / radius, -1.0 / radius]))[0][:2], on_straight[:2])
    np.testing.assert_array_equal(curved(e)[0], on_straight)  # no curvature given: a straight
    assert _front_on_the_turn_back_in_a_corner(e0, -1.0 / radius) > _front_on_the_turn_back(e0) - 1e-9


def test_curved_envelope_is_finite_in_a_hairpin_and_its_slopes_are_the_derivatives():
    ends = EndOffsets(AV21, recoverable=True, curved=True)
    k_up, k_lo = ends.turn_back_curvatures(np.array([-1.0, 0.0, 0.02, 1.0]))
    np.testing.assert_allclose(k_up, [0.25 * ends.curvature, ends.curvature, ends.curvature, ends.curvature])
    np.testing.assert_allclose(k_lo, [ends.curvature, ends.curvature, ends.curvature - 0.02, 0.25 * ends.curvature])
    e = np.linspace(-1.2, 1.2, 97)
    kappa = np.linspace(-0.08, 0.08, 97)
    h = 1e-6
    values, slopes = ends(e, kappa)
    assert np.isfinite(values).all()
    fd = (ends(e + h, kappa)[0] - ends(e - h, kappa)[0]) / (2 * h)
    np.testing.assert_allclose(slopes, fd, atol=1e-4)


def test_curved_envelope_symbolic_form_is_the_numeric_one():
    import casadi as ca

    ends = EndOffsets(AV21, recoverable=True, curved=True)
    e, k = ca.SX.sym("e"), ca.SX.sym("k")
    f = ca.Function("f", [e, k], [ca.vertcat(*ends.symbolic(e, k))])
    for e0, k0 in [(0.9, 0.04), (-0.9, 0.04), (0.5, -0.03), (0.1, 0.06), (-1.1, -1.0)]:
        np.testing.assert_allclose(np.array(f(e0, k0)).ravel(), ends(np.array([e0]), np.array([k0]))[0][:, 0],
                                   atol=1e-12)


def test_curved_rows_in_a_corner_match_the_ipopt_reference(cache_dir):
    """At 3 m/s, 2.5 m left and turned 0.5 rad towards the left edge in a right-hand corner of 40 m radius, pulled
    further left: the RTI with the curved rows converges to the IPOPT reference of the same problem (the rows see
    each stage's curvature); both plans run the front row to its bound, and with the corner counted the car brakes
    harder, since turning back there takes more room."""
    x0 = np.array([0.0, 2.5, 0.5, 3.0, 0.0])
    stage = make_stage(v_ref=10.0, n_ref=5.5, kappa=-1.0 / 40.0, half_width=6.0)
    out = {}
    for rows in ("recoverable", "recoverable-curved"):
        cfg, res, _ = _rti_and_reference(rows, cache_dir, x0, stage, atol=1e-5)
        values, _ = EndOffsets.for_rows(rows, AV21)(res.x_pred[1:, 2], stage.kappa[1:])
        assert (res.x_pred[1:, 1] + values[0]).max() == pytest.approx(6.0 - cfg.track_margin, abs=1e-3)
        assert res.slack["track"] < 1e-6
        out[rows] = res
    assert out["recoverable-curved"].u[0] < out["recoverable"].u[0] - 1.0 < 0.0
