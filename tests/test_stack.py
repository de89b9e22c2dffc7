"""The hierarchical controller (Algorithm 1) in closed loop with the race world."""

from __future__ import annotations

import math
from dataclasses import replace

import gymnasium as gym
import numpy as np
import pytest

import sofar_env  # noqa: F401  (registers the environments)
from sofar_env.opponents import OpponentConfig
from sofar_env.planning.miqp import PassingSidePlanner
from sofar_env.race import Race, RaceConfig
from sofar_env.stack import OvertakingStack, StackConfig
from sofar_env.tracks import Track

SETTLE = 5.0  # s


@pytest.fixture(scope="module")
def tracks():
    return {name: Track.load(name) for name in ("LagunaSeca", "Monza", "Indianapolis", "Kentucky")}


def empty_race(track, start_s: float = 0.0, speed_factor: float = 0.8) -> Race:
    """A race without opponents, the ego on the raceline at ``start_s`` at its reference speed."""
    race = Race(track, RaceConfig(random_start=False, duration=1e4, opponents=OpponentConfig(n_opponents=0)))
    race.reset(np.random.default_rng(0), start_s=start_s,
               start_speed=speed_factor * float(track.speed(start_s)), n_opponents=0)
    return race


def drive(race: Race, stack: OvertakingStack, gamma: float, steps: int | None = None, laps: float | None = None):
    """Run the stack in the race; returns per-step (time, n) and whether the car ever left the track."""
    t, n, off = [], [], False
    k = 0
    while (steps is None or k < steps) and (laps is None or race.laps() < laps):
        out = stack.step(race.frenet[0], race.opponent_frenet(0), gamma)
        ev = race.step(out.u[None, :])[0]
        off |= ev.off_track
        t.append(race.time)
        n.append(race.frenet[0, 1])
        k += 1
        assert k < 5000, "no lap within 5000 steps"
    return np.array(t), np.array(n), off


@pytest.mark.parametrize("name", ["LagunaSeca", "Monza", "Indianapolis", "Kentucky"])
def test_tracks_the_raceline_over_a_lap_without_opponents(tracks, name):
    track = tracks[name]
    race = empty_race(track)
    stack = OvertakingStack(track, StackConfig(speed_factor=0.8))
    t, n, off = drive(race, stack, gamma=0.5, laps=1.0)
    assert race.laps() >= 1.0
    assert not off
    assert np.max(np.abs(n[t >= SETTLE])) <= 0.3
    assert stack.counters["mpc_failures"] == 0 and stack.counters["miqp_failures"] == 0
    assert stack.counters["follow_steps"] == 0


def test_overtakes_on_laguna_seca_without_collision_or_leaving_the_track():
    env = gym.make("SOfAR-LagunaSeca-v0", rho=0.3, n_opponents=4, config={"race": {"duration": 60.0}})
    env.reset(seed=1234)
    collision = off_track = False
    info = {}
    for _ in range(600):
        _, _, terminated, truncated, info = env.step(np.array([0.5], np.float32))
        collision |= info["collision"]
        off_track |= info["off_track"]
        if terminated or truncated:
            break
    env.close()
    assert info["sim_time"] == pytest.approx(60.0)
    assert not collision and not off_track
    assert info["overtakes"] >= 1


def test_without_the_miqp_the_mpc_tracks_the_raceline(tracks):
    track = tracks["LagunaSeca"]
    race = empty_race(track, start_s=500.0)
    stack = OvertakingStack(track, StackConfig(use_miqp=False))
    out = stack.step(race.frenet[0], np.zeros((0, 3)), 0.5)
    assert out.plan is None and not out.miqp_ran and not out.following
    np.testing.assert_array_equal(stack.stage_data(race.frenet[0, 0]).n_ref, 0.0)
    race.step(out.u[None, :])
    t, n, off = drive(race, stack, gamma=0.5, steps=300)
    assert not off
    assert np.max(np.abs(n[t >= SETTLE])) <= 0.3
    assert stack.counters["miqp_solves"] == 0


def test_without_the_miqp_the_stack_still_races_opponents():
    """The Table II ablation: the MPC-DCBF alone, opponents avoided by the barrier only."""
    env = gym.make("SOfAR-LagunaSeca-v0", rho=0.5, n_opponents=4, use_miqp=False,
                   config={"race": {"duration": 20.0}})
    env.reset(seed=3)
    for _ in range(200):
        _, _, terminated, truncated, info = env.step(np.array([0.3], np.float32))
        assert info["miqp_sides"] == ()
        if terminated or truncated:
            break
    assert env.unwrapped.stack.counters["miqp_solves"] == 0
    assert info["laps"] > 0.0
    env.close()


def test_an_opponent_inside_the_ellipse_does_not_raise(tracks):
    track = tracks["LagunaSeca"]
    race = empty_race(track, start_s=500.0)
    stack = OvertakingStack(track)
    s, n, _, v, _ = race.frenet[0]
    # right beside and overlapping the ego (h ~ -1), and one just ahead in its lane
    opponents = np.array([[s + 0.5, n + 0.3, 0.5 * v], [s + 4.0, n, 0.2 * v]])
    for k in range(20):
        out = stack.step(race.frenet[0], opponents, 0.9)
        assert np.all(np.isfinite(out.u))
        assert race.config.vehicle.a_min <= out.u[0] <= race.config.vehicle.a_max
        if k == 0:
            assert out.mpc.barrier_min < -0.5
        race.step(out.u[None, :])
        opponents[:, 0] += opponents[:, 2] * race.config.dt
    c = stack.counters
    assert c["steps"] == 20 and c["miqp_solves"] >= 10
    assert set(c) >= {"steps", "mpc_failures", "miqp_failures", "miqp_solves", "follow_steps"}


def test_failures_are_counted_not_raised(tracks, monkeypatch):
    track = tracks["LagunaSeca"]
    race = empty_race(track, start_s=500.0)
    stack = OvertakingStack(track)
    opponents = np.array([[race.frenet[0, 0] + 30.0, 0.0, 10.0]])
    stack.step(race.frenet[0], opponents, 0.5)
    assert stack.counters["mpc_failures"] == 0 and stack.counters["miqp_failures"] == 0
    # an MPC failure: a steering angle beyond what the hard bounds can bring back in one step
    bad = race.frenet[0].copy()
    bad[4] = 0.6
    out = stack.step(bad, opponents, 0.5)
    assert not out.mpc.success and np.all(np.isfinite(out.u))
    assert stack.counters["mpc_failures"] == 1
    # an MIQP failure: every solver route fails -> fallback plan, counted
    monkeypatch.setattr(PassingSidePlanner, "_solve_bnb", lambda self, prob: None)
    monkeypatch.setattr(PassingSidePlanner, "_solve_enumerate", lambda self, prob: None)
    for _ in range(2):  # the MIQP runs every other step
        out = stack.step(race.frenet[0], opponents, 0.5)
    assert stack.counters["miqp_failures"] >= 1
    assert out.plan is not None and not out.plan.success
    assert np.all(np.isfinite(out.u))


def test_follows_an_opponent_it_cannot_pass(tracks):
    """A car on the raceline of Kentucky's narrowest part, too narrow for the passing clearance:
    the stack follows it (speed capped, no side chosen) instead of squeezing past."""
    track = tracks["Kentucky"]
    s = np.linspace(0.0, track.length, 3000, endpoint=False)
    width = np.asarray(track.width_left(s) + track.width_right(s))
    s0 = float(s[np.argmin(width)]) - 150.0
    race = empty_race(track, start_s=s0)
    stack = OvertakingStack(track)
    v_opp = 0.5 * float(race.frenet[0, 3])
    opponent = np.array([[s0 + 60.0, 0.0, v_opp]])
    followed = False
    for k in range(30):
        opponent[0, 0] += 0.0 if k == 0 else v_opp * race.config.dt
        out = stack.step(race.frenet[0], opponent, 0.5)
        ev = race.step(out.u[None, :])[0]
        assert not ev.collision and not ev.off_track
        followed |= out.following
    assert followed
    assert stack.counters["follow_steps"] > 0


@pytest.mark.parametrize("recheck", [1, 2])
def test_follow_recheck_skips_the_passing_solve_between_examinations(tracks, recheck):
    """The Kentucky follow scenario above: with ``follow_recheck = 1`` every MIQP call while
    following solves the passing plan and the follow plan; with 2, every other call re-solves
    only the follow plan (one solve), and the ego keeps following without a collision."""
    track = tracks["Kentucky"]
    s = np.linspace(0.0, track.length, 3000, endpoint=False)
    width = np.asarray(track.width_left(s) + track.width_right(s))
    s0 = float(s[np.argmin(width)]) - 150.0
    race = empty_race(track, start_s=s0)
    stack = OvertakingStack(track, StackConfig(follow_recheck=recheck))
    solves = []
    plan = stack.planner.plan

    def counted(*args, **kwargs):
        solves[-1] += 1
        return plan(*args, **kwargs)

    stack.planner.plan = counted
    v_opp = 0.5 * float(race.frenet[0, 3])
    opponent = np.array([[s0 + 60.0, 0.0, v_opp]])
    per_call = []  # (following before the call, solves in the call)
    for k in range(40):
        opponent[0, 0] += 0.0 if k == 0 else v_opp * race.config.dt
        was_following = stack._follow is not None
        solves.append(0)
        out = stack.step(race.frenet[0], opponent, 0.5)
        if out.miqp_ran:
            per_call.append((was_following, solves[-1]))
        ev = race.step(out.u[None, :])[0]
        assert not ev.collision and not ev.off_track
    while_following = [n for was, n in per_call if was]
    assert len(while_following) >= 5
    if recheck == 1:  # two solves per call; one only in the call that resumes the pass
        assert while_following.count(1) <= 1
    else:
        assert while_following.count(1) >= (len(while_following) - 1) // 2


def test_followed_cars_are_found_again_by_their_predicted_position(tracks):
    stack = OvertakingStack(tracks["Monza"])
    rows = np.array([[40.0, 0.0, 30.0]])
    stack._plan_s, stack._step = 100.0, 10
    follow = (rows, 8)  # recorded 2 steps (0.2 s) ago, when the ego was at s = 100 m
    ego_s = 110.0  # the ego has advanced 10 m since
    pred = stack.predict_opponents(100.0, rows, np.array([0.2]))[0, 0] - 10.0
    opp_rel = np.array([[pred + 0.5, -3.0, 30.0], [pred - 0.4, 0.1, 30.0], [80.0, 0.0, 25.0]])
    assert stack._followed_rows(ego_s, opp_rel, follow).tolist() == [False, True, False]
    assert stack._followed_rows(ego_s, opp_rel[[0, 2]], follow) is None  # the car is gone (overtaken)
    assert stack._followed_rows(ego_s, np.zeros((0, 3)), follow) is None


def test_can_stay_behind_a_car_alongside_only_if_braking_drops_the_ego_back(tracks):
    """The follow decision's reachability test: a car alongside at equal speed is followable (hard
    braking drops the ego behind it) with ``follow_alongside``, not without; a car being closed on
    fast from 20 m is never followable; one 30 m ahead at equal speed always is."""
    track = tracks["Monza"]
    times = np.arange(StackConfig().miqp.nodes) * StackConfig().miqp.node_dt
    v = 30.0
    gaps = np.array([1.0, 20.0, 30.0])
    speeds = np.array([v, 0.2 * v, v])
    opp_s = gaps[:, None] + speeds[:, None] * times[None, :]  # constant speed, relative to the ego now
    with_alongside = OvertakingStack(track)._can_stay_behind(v, gaps, opp_s)
    without = OvertakingStack(track, StackConfig(follow_alongside=False))._can_stay_behind(v, gaps, opp_s)
    assert with_alongside.tolist() == [True, False, True]
    assert without.tolist() == [False, False, True]


@pytest.mark.parametrize("rho, seed, gamma, until, overtakes", [
    # the ego ends up alongside a car as the left edge closes in at the last corner; holding
    # the pass squeezed it into that car at 110.5 s (with follow_alongside=False and
    # follow_release_slack=0.5; either fix alone avoids it)
    (0.65, 3252676551, 0.5, 112.0, 4),
    # at the same corner the follow decision flickered at every MIQP call (no hysteresis,
    # follow_release_slack = follow_slack), trading braking for pass attempts until a
    # collision at 119.6 s
    (0.3, 1531305125, 0.05, 121.0, 14),
])
def test_laguna_seca_last_corner_regressions(rho, seed, gamma, until, overtakes):
    """Closed-loop regressions from evaluation episodes on Laguna Seca (the stack's defaults)."""
    env = gym.make("SOfAR-LagunaSeca-v0")
    env.reset(seed=seed, options={"rho": rho})
    info = {}
    while not info or info["sim_time"] < until:
        _, _, terminated, truncated, info = env.step(np.array([gamma], np.float32))
        assert not terminated, f"collision/off-track at {info['sim_time']:.1f} s"
    assert info["overtakes"] >= overtakes
    env.close()


def test_follow_release_slack_is_validated():
    with pytest.raises(ValueError, match="follow_release_slack"):
        StackConfig(follow_release_slack=0.6)
    with pytest.raises(ValueError, match="follow_recheck"):
        StackConfig(follow_recheck=0)
