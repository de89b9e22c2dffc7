"""The control step of Algorithm 1 (OvertakingStack) in closed loop with the race world."""

from __future__ import annotations

import dataclasses
import math

import gymnasium as gym
import numpy as np
import pytest

import sofar_env  # noqa: F401  (registers the environments)
from sofar_env.planning.miqp import PassingSidePlanner
from sofar_env.stack import OvertakingStack, StackConfig

from .closed_loop import SETTLE, drive, empty_race


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


def test_the_miqp_runs_every_miqp_interval_steps(tracks):
    track = tracks["Monza"]
    race = empty_race(track, start_s=300.0)
    stack = OvertakingStack(track, StackConfig(miqp_interval=3))
    ran = []
    for _ in range(7):
        out = stack.step(race.frenet[0], np.zeros((0, 3)), 0.5)
        ran.append(out.miqp_ran)
        assert out.plan is not None and (not out.miqp_ran or out.plan_s == out.ego_s)
        race.step(out.u[None, :])
    assert ran == [True, False, False, True, False, False, True]
    assert stack.counters["miqp_solves"] == 3


def test_gamma_is_validated(tracks):
    stack = OvertakingStack(tracks["Monza"])
    race = empty_race(tracks["Monza"], start_s=300.0)
    for gamma in (0.0, 1.5, float("nan")):
        with pytest.raises(ValueError, match="gamma"):
            stack.step(race.frenet[0], np.zeros((0, 3)), gamma)


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


def test_reset_forgets_the_plan_and_the_counters(tracks):
    track = tracks["Kentucky"]
    race = empty_race(track, start_s=200.0)
    stack = OvertakingStack(track)
    for _ in range(3):
        stack.step(race.frenet[0], np.array([[race.frenet[0, 0] + 40.0, 0.0, 20.0]]), 0.5)
    stack.reset()
    assert stack.counters["steps"] == 0 and stack.counters["miqp_solves"] == 0
    assert not stack.following and stack.pass_or_follow.target is None
    assert stack.step(race.frenet[0], np.zeros((0, 3)), 0.5).miqp_ran


@pytest.mark.parametrize("name, preset", [("LagunaSeca", "sofar-ends"), ("Monza", "sofar-ends"),
                                          ("LagunaSeca", "sofar-recover"), ("Monza", "sofar-recover")])
def test_the_end_row_presets_lap_on_the_raceline(tracks, name, preset):
    """``stack="sofar-ends"`` / ``"sofar-recover"``: the MPC bounds both ends of the car in its QP; on an
    empty track it drives the raceline as the default stack does."""
    from sofar_env.stack import stack_preset

    track = tracks[name]
    race = empty_race(track)
    stack = OvertakingStack(track, stack_preset(preset))
    t, n, off = drive(race, stack, gamma=0.5, laps=1.0)
    assert race.laps() >= 1.0 and not off
    assert np.max(np.abs(n[t >= SETTLE])) <= 0.3
    assert stack.counters["mpc_failures"] == 0


@pytest.mark.parametrize("preset, rows", [("sofar-ends", "ends"), ("sofar-recover", "recoverable")])
def test_the_end_row_presets_give_the_mpc_edges_without_the_frozen_heading_swing(tracks, preset, rows):
    from sofar_env.stack import stack_preset

    track = tracks["LagunaSeca"]
    race = empty_race(track)
    # the end-row presets are version 1 ("sofar-1") with other track rows
    default, ends = OvertakingStack(track, stack_preset("sofar-1")), OvertakingStack(track, stack_preset(preset))
    assert ends.config.mpc.track_rows == rows and default.config.mpc.track_rows == "reference"
    assert dataclasses.replace(ends.config, mpc=default.config.mpc) == default.config  # nothing else differs
    for stack in (default, ends):
        stack.step(race.frenet[0], race.opponent_frenet(0), 0.5)
        stack._last_pred[:, 2] = 0.3  # a previous plan turned 0.3 rad from the track's direction
    s = float(race.frenet[0, 0])
    s_abs = s + np.asarray(ends.mpc.predicted_s(), float)
    n_min, n_max = ends.edges(s_abs)
    stage = ends.stage_data(s)
    np.testing.assert_array_equal(stage.n_min, n_min)
    np.testing.assert_array_equal(stage.n_max, n_max)
    swing = max(default.vehicle.cg_to_front, default.vehicle.cg_to_rear) * math.sin(0.3)
    stage = default.stage_data(s)
    np.testing.assert_allclose(stage.n_max, default.edges(s + np.asarray(default.mpc.predicted_s(), float))[1] - swing)
