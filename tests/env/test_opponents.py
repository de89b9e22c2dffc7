"""The opponent field: the paper's motion by default, and the behaviours that race back.

Everything runs on the shipped Laguna Seca circuit (a narrow road course: the
tightest test of staying inside the edges).
"""

import math

import numpy as np
import pytest

from sofar_env.geometry import footprint_corners, rectangles_intersect
from sofar_env.opponents import DefenceConfig, LineConfig, OpponentConfig, Opponents, PaceConfig, TrafficConfig
from sofar_env.opponents.defence import HOLDING, IDLE, MOVING
from sofar_env.tracks import Track
from sofar_env.vehicle import AV21

DT = 0.1
WIDE_LEFT = 480.0
"""From here Laguna Seca is at least 5 m wide on the left of the raceline for 300 m."""


@pytest.fixture(scope="module")
def track():
    return Track.load("LagunaSeca")


def old_motion(track, s0, n0, rho, steps):
    """The paper's opponents, written out: constant offset, midpoint rule at rho x the speed profile."""
    s, rows = np.array(s0, float), []
    for _ in range(steps):
        s = np.array([track.wrap(x + DT * rho * track.speed(x + 0.5 * DT * rho * track.speed(x))) for x in s])
        rows.append((s.copy(), np.array(n0, float), np.array([rho * track.speed(float(x)) for x in s])))
    return rows


def corners_on_track(track, op):
    x, y, psi = op.poses()
    for i, car in enumerate(footprint_corners(x, y, psi, AV21)):
        for cx, cy in car:
            s, n = track.to_frenet(float(cx), float(cy), s_hint=float(op.s[i]))
            if n > track.width_left(s) or n < -track.width_right(s):
                return False
    return True


def any_overlap(op):
    x, y, psi = op.poses()
    c = footprint_corners(x, y, psi, AV21)
    return any(rectangles_intersect(c[a], c[b]) for a in range(op.count) for b in range(a + 1, op.count))


# ----------------------------------------------------------------------------- the paper's field
def test_defaults_reproduce_the_paper_motion_bit_for_bit_and_draw_nothing(track):
    cfg = OpponentConfig(n_opponents=6)
    assert not cfg.interactive
    op = Opponents(track, cfg)
    rng = np.random.default_rng(5)
    state = rng.bit_generator.state
    op.reset(1000.0, rho=0.5, rng=rng)
    assert rng.bit_generator.state == state  # no random number drawn
    n0 = [cfg.offset(i) for i in range(6)]
    expected = old_motion(track, [track.wrap(1000.0 + cfg.gap(i)) for i in range(6)], n0, 0.5, 200)
    for k in range(200):
        op.advance(DT, ego=(1000.0 + 30.0 * k * DT, 2.0, 30.0) if k % 2 else None)  # the ego is ignored
        s, n, v = expected[k]
        assert np.array_equal(op.s, s) and np.array_equal(op.n, n) and np.array_equal(op.v, v)
        assert np.array_equal(op.n_dot, np.zeros(6))
    x, y, psi = op.poses()
    for i in range(6):
        assert (x[i], y[i], psi[i]) == track.pose(float(op.s[i]), float(op.n[i]))  # yaw: the raceline heading


def test_an_interactive_field_needs_an_rng(track):
    op = Opponents(track, OpponentConfig(pace=PaceConfig(spread=0.1)))
    with pytest.raises(ValueError, match="rng"):
        op.reset(0.0)


def test_invalid_settings_raise():
    for make in (lambda: PaceConfig(spread=1.0), lambda: PaceConfig(lift_ramp=3.0, lift_duration=4.0),
                 lambda: LineConfig(amplitude=-1.0), lambda: LineConfig(wavelengths=(900.0, 300.0)),
                 lambda: DefenceConfig(min_gap=60.0, max_gap=5.0), lambda: DefenceConfig(never_defend=1.5),
                 lambda: DefenceConfig(aggressiveness=(0.0, 1.0)), lambda: TrafficConfig(follow_gap=0.0)):
        with pytest.raises(ValueError):
            make()


# ----------------------------------------------------------------------------- seeding
ALL_ON = OpponentConfig(n_opponents=6, rho=0.6, pace=PaceConfig(spread=0.15, lift_rate=0.1),
                        lines=LineConfig(amplitude=2.0), defence=DefenceConfig(enabled=True, never_defend=0.0))


def run_field(track, cfg, seed, steps=300):
    op = Opponents(track, cfg)
    op.reset(100.0, rng=np.random.default_rng(seed))
    ego_s, out = 100.0, []
    for k in range(steps):
        v = 0.75 * track.speed(ego_s)
        op.advance(DT, (ego_s, 2.0 * math.sin(ego_s / 150.0), v))
        ego_s = track.wrap(ego_s + DT * v)
        op.update_overtakes(ego_s)
        out.append(np.concatenate([op.s, op.n, op.v, op.n_dot]))
    return np.array(out)


def test_same_seed_same_field_other_seed_other_field(track):
    a, b, c = (run_field(track, ALL_ON, seed) for seed in (3, 3, 4))
    assert np.array_equal(a, b)
    assert not np.array_equal(a, c)


# ----------------------------------------------------------------------------- pace
def test_pace_ratios_are_uniform_around_rho(track):
    spread, rho = 0.15, 0.5
    op = Opponents(track, OpponentConfig(n_opponents=500, rho=rho, pace=PaceConfig(spread=spread)))
    paces = np.concatenate([(op.reset(0.0, rng=np.random.default_rng(seed)), op.episode.pace.copy())[1]
                            for seed in range(4)])
    assert paces.min() >= rho * (1 - spread) and paces.max() <= rho * (1 + spread)
    assert paces.mean() == pytest.approx(rho, abs=0.005)
    assert paces.std() == pytest.approx(rho * spread / math.sqrt(3.0), rel=0.05)
    assert np.allclose(op.v, op.episode.pace * track.speed(op.s))


def test_lifts_dip_smoothly_to_the_lift_depth_and_recover(track):
    pace = PaceConfig(lift_rate=0.2, lift_depth=0.7, lift_duration=4.0, lift_ramp=1.5)
    op = Opponents(track, OpponentConfig(n_opponents=1, rho=0.5, offsets=(0.0,), gaps=(100.0,), pace=pace))
    op.reset(0.0, rng=np.random.default_rng(0))
    ratios = []
    for _ in range(3000):  # 300 s
        op.advance(DT)
        ratios.append(op.v[0] / (0.5 * track.speed(float(op.s[0]))))
    r = np.array(ratios)
    assert r.max() <= 1.0 + 1e-12 and r.min() >= 0.7 - 1e-12
    assert r.min() < 0.701  # the bottom of a lift is reached
    lifts = int(np.sum((r[1:] < 1.0) & (r[:-1] == 1.0)))
    assert 15 <= lifts <= 55  # about 300 s / (1 / 0.2 + 4) = 33
    # a ramp, not a jump: the steepest change of the raised cosine is pi (1 - depth) / (2 ramp) per second
    assert np.abs(np.diff(r)).max() <= math.pi * 0.3 / (2 * 1.5) * DT + 1e-9


def test_a_faster_car_does_not_close_below_the_follow_gap(track):
    cfg = OpponentConfig(n_opponents=2, rho=0.5, offsets=(0.0, 0.0), gaps=(100.0, 140.0), pace=PaceConfig(spread=0.01))
    op = Opponents(track, cfg)
    op.reset(0.0, rng=np.random.default_rng(0))
    op.episode.pace[:] = (0.8, 0.4)  # the car behind is twice as fast
    gaps = []
    for _ in range(600):
        op.advance(DT)
        gaps.append(track.gap(float(op.s[1]), float(op.s[0])))
    assert min(gaps) >= cfg.traffic.follow_gap - 1e-9
    assert gaps[-1] < 12.5  # it caught up and follows


# ----------------------------------------------------------------------------- lines
@pytest.mark.parametrize("amplitude", [1.0, 3.0])
def test_lines_stay_inside_the_edges_with_bounded_lateral_rate_and_acceleration(track, amplitude):
    lines = LineConfig(amplitude=amplitude)
    op = Opponents(track, OpponentConfig(n_opponents=4, rho=0.8, lines=lines))
    op.reset(0.0, rng=np.random.default_rng(1))
    nd, ns = op.n_dot.copy(), []
    for k in range(1500):
        op.advance(DT)
        assert np.abs(op.n_dot).max() <= lines.lateral_speed + 1e-12
        assert np.abs(op.n_dot - nd).max() <= lines.lateral_accel * DT + 1e-12
        nd = op.n_dot.copy()
        ns.append(op.n.copy())
        if k % 10 == 0:
            assert corners_on_track(track, op)
    assert op.clamps == 0
    assert np.ptp(np.array(ns), axis=0).min() > 0.5 * amplitude  # every car does move about its line
    assert np.ptp(np.array(ns)) <= 2 * amplitude + 2.0 + 1e-9  # offsets in [-1, 1] plus the line


def test_the_lateral_motion_turns_the_pose(track):
    op = Opponents(track, OpponentConfig(n_opponents=4, rho=0.8, lines=LineConfig(amplitude=2.0)))
    op.reset(0.0, rng=np.random.default_rng(1))
    for _ in range(50):
        op.advance(DT)
    _, _, psi = op.poses()
    i = int(np.argmax(np.abs(op.n_dot)))
    assert op.n_dot[i] != 0.0
    kappa = track.curvature(float(op.s[i]))
    heading = track.pose(float(op.s[i]), float(op.n[i]))[2]
    assert psi[i] == pytest.approx(heading + math.atan2(op.n_dot[i], (1 - kappa * op.n[i]) * op.v[i]), abs=1e-12)


# ----------------------------------------------------------------------------- defending
def defending_field(track, gap=70.0, **defence):
    d = dict(enabled=True, never_defend=0.0, aggressiveness=(1.0, 1.0))
    d.update(defence)
    cfg = OpponentConfig(n_opponents=1, rho=0.3, offsets=(0.0,), gaps=(gap,), defence=DefenceConfig(**d))
    op = Opponents(track, cfg)
    op.reset(WIDE_LEFT, rng=np.random.default_rng(0))
    return op


def approach(track, op, ego_n, steps, closing=4.0, ego_s=WIDE_LEFT):
    """Drive a scripted ego ``closing`` faster than the car; ``ego_n(k, gap)`` gives its offset."""
    log = []
    for k in range(steps):
        gap = float(track.gap(float(op.s[0]), ego_s))
        n_e = ego_n(k, gap)
        v_e = float(op.v[0]) + closing
        n_before = float(op.n[0])
        op.advance(DT, (ego_s, n_e, v_e))
        ep = op.episode.defence if op.episode is not None else None  # None: the paper's field
        log.append(dict(gap=gap, n_ego=n_e, n=float(op.n[0]), n_before=n_before,
                        mode=int(ep.mode[0]) if ep else IDLE, moves=int(ep.moves[0]) if ep else 0))
        ego_s = track.wrap(ego_s + DT * v_e)
    return log, ego_s


def test_a_defending_car_moves_toward_the_ego_line_inside_the_track(track):
    op = defending_field(track)
    log, _ = approach(track, op, lambda k, g: 2.5, steps=120)
    assert log[0]["gap"] > 60.0 and log[0]["mode"] == IDLE
    started = next(k for k, row in enumerate(log) if row["mode"] == MOVING)
    assert 5.0 <= log[started]["gap"] <= 60.0
    assert max(row["n"] for row in log) > 2.0  # it went (most of the way) over to block
    assert all(row["n"] >= row["n_before"] - 1e-12 for row in log)  # only toward the ego's side
    assert log[-1]["moves"] == 1
    assert corners_on_track(track, op)
    assert np.abs(np.diff([row["n"] for row in log])).max() <= 1.5 * DT + 1e-9  # lateral speed bound


def test_one_move_per_approach_and_a_new_one_after_the_ego_fell_back(track):
    op = defending_field(track)
    # the ego shows the left, then (after the car has moved) switches to the right
    log, ego_s = approach(track, op, lambda k, g: 2.5 if k < 60 else -1.5, steps=110)
    assert log[-1]["moves"] == 1
    n_hold = log[59]["n"]
    assert all(row["n"] >= n_hold - 0.3 for row in log[60:])  # it does not follow the switch (holds, brakes)
    # the ego falls back beyond the window: the approach ends; on the next approach one more move
    log2, ego_s = approach(track, op, lambda k, g: -1.5, steps=80, closing=-8.0, ego_s=ego_s)
    assert log2[-1]["gap"] > op.config.defence.max_gap + op.config.defence.release
    log3, _ = approach(track, op, lambda k, g: 2.5, steps=60, closing=6.0, ego_s=ego_s)
    assert log3[-1]["moves"] == 2


def test_no_move_once_the_ego_is_alongside(track):
    op = defending_field(track, gap=70.0)
    along = AV21.length + op.config.defence.alongside_margin
    # straight behind (no side shown, no move) until alongside, then on the left
    log, _ = approach(track, op, lambda k, g: 0.0 if g > along else 3.0, steps=260, closing=3.0)
    alongside = [row for row in log if abs(row["gap"]) < along]
    assert alongside, "the ego must come alongside in this scenario"
    assert log[-1]["moves"] == 0
    assert all(row["n"] == 0.0 for row in log)


def test_a_move_stops_once_the_ego_is_alongside_and_never_closes_on_it(track):
    # the ego shows the left 14 m behind, closing fast: the car starts its move but may close on the
    # ego's line only down to the clearance, and the move ends when the ego is alongside
    op = defending_field(track, gap=14.0)
    along = AV21.length + op.config.defence.alongside_margin
    clearance = AV21.width + op.config.defence.clearance
    log, _ = approach(track, op, lambda k, g: 3.2, steps=40, closing=6.0)
    assert log[0]["mode"] == MOVING and log[-1]["moves"] == 1
    assert max(row["n"] for row in log) > 0.1  # it did move toward the ego ...
    for row in log:
        assert abs(row["n_ego"] - row["n"]) >= clearance - 1e-9  # ... but never into it
        if abs(row["gap"]) < along:
            assert row["mode"] in (HOLDING, IDLE)
    # already closer than the clearance when the ego comes alongside: it does not close at all
    op = defending_field(track, gap=30.0)
    log, _ = approach(track, op, lambda k, g: 3.2, steps=120, closing=6.0)
    for row in log:
        if abs(row["gap"]) < along:
            assert abs(row["n_ego"] - row["n"]) >= min(clearance, abs(row["n_ego"] - row["n_before"])) - 1e-9


def test_never_defend_one_never_moves(track):
    op = defending_field(track, never_defend=1.0)
    assert not op.config.interactive  # nothing on: the paper's field
    log, _ = approach(track, op, lambda k, g: 2.5, steps=150)
    assert all(row["n"] == 0.0 for row in log)
    op2 = Opponents(track, OpponentConfig(n_opponents=1, rho=0.3, offsets=(0.0,), gaps=(70.0,),
                                          lines=LineConfig(amplitude=1e-9),
                                          defence=DefenceConfig(enabled=True, never_defend=1.0)))
    op2.reset(WIDE_LEFT, rng=np.random.default_rng(0))
    approach(track, op2, lambda k, g: 2.5, steps=150)
    assert op2.episode.defence.moves[0] == 0 and abs(op2.n[0]) < 1e-6


def test_a_respawned_car_gets_a_new_id_and_fresh_approach_state(track):
    op = defending_field(track, gap=30.0)
    log, ego_s = approach(track, op, lambda k, g: 2.5, steps=5, closing=6.0)
    assert op.episode.defence.approach[0]
    old_id = int(op.ids[0])
    passed = op.update_overtakes(track.wrap(float(op.s[0]) + 5.0))  # the ego is past the car
    assert list(passed) == [0]
    assert int(op.ids[0]) != old_id
    assert not op.episode.defence.approach[0] and op.episode.defence.mode[0] == IDLE
    assert op.n_dot[0] == 0.0


# ----------------------------------------------------------------------------- the whole field
def test_a_busy_field_never_overlaps_nor_leaves_the_track(track):
    cfg = OpponentConfig(n_opponents=8, rho=0.6, pace=PaceConfig(spread=0.15, lift_rate=0.05),
                         lines=LineConfig(amplitude=3.0), defence=DefenceConfig(enabled=True, never_defend=0.0))
    op = Opponents(track, cfg)
    op.reset(100.0, rng=np.random.default_rng(1))
    ego_s = 100.0
    for k in range(2500):
        v = 0.75 * track.speed(ego_s)
        op.advance(DT, (ego_s, 3.0 * math.sin(ego_s / 150.0), v))
        ego_s = track.wrap(ego_s + DT * v)
        assert not any_overlap(op), f"overlap at step {k}"
        if k % 5 == 0:
            assert corners_on_track(track, op), f"off track at step {k}"
        op.update_overtakes(ego_s)
    assert op.episode.defence.moves.sum() > 0
    assert op.clamps < 0.01 * 2500 * 8  # the hard stops stay rare
