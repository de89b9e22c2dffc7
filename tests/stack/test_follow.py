"""Pass or follow: following an opponent that cannot be passed (sofar_env.stack.follow)."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import piqp
import pytest

import sofar_env  # noqa: F401  (registers the environments)
from sofar_env.stack import OvertakingStack, StackConfig
from sofar_env.stack.follow import FollowTarget

from .closed_loop import empty_race, narrowest_approach

# A seeded episode is bit-for-bit reproducible on one instruction set, not across them: PIQP loads its
# AVX-512 or its AVX2 build by the CPU, and numpy and OpenBLAS pick their kernels the same way, so the
# last bits of a solve differ and a closed loop of a thousand steps drifts apart.
_AVX512 = bool(getattr(piqp.instruction_set, "avx512f", False))


def test_follows_an_opponent_it_cannot_pass(tracks):
    """A car on the raceline of Kentucky's narrowest part, too narrow for the passing clearance:
    the stack follows it (speed capped, no side chosen) instead of squeezing past."""
    track = tracks["Kentucky"]
    s0 = narrowest_approach(track)
    race = empty_race(track, start_s=s0)
    stack = OvertakingStack(track)
    v_opp = 0.5 * float(race.frenet[0, 3])
    opponent = np.array([[s0 + 60.0, 0.0, v_opp]])
    followed = capped = False
    for k in range(30):
        opponent[0, 0] += 0.0 if k == 0 else v_opp * race.config.dt
        out = stack.step(race.frenet[0], opponent, 0.5)
        ev = race.step(out.u[None, :])[0]
        assert not ev.collision and not ev.off_track
        followed |= out.following
        if out.following:
            ego_s = out.ego_s
            cap = stack.pass_or_follow.speed_cap(ego_s, np.asarray(stack.mpc.predicted_s(), float),
                                                 stack._mpc_t, stack._step)
            free = stack.config.speed_factor * np.asarray(track.speed(ego_s + stack.mpc.predicted_s()))
            capped |= bool((cap < free).any())
    assert followed and capped
    assert stack.counters["follow_steps"] > 0


def test_without_follow_the_stack_never_follows(tracks):
    track = tracks["Kentucky"]
    s0 = narrowest_approach(track)
    race = empty_race(track, start_s=s0)
    stack = OvertakingStack(track, StackConfig(follow=False))
    v_opp = 0.5 * float(race.frenet[0, 3])
    opponent = np.array([[s0 + 60.0, 0.0, v_opp]])
    for k in range(10):
        opponent[0, 0] += 0.0 if k == 0 else v_opp * race.config.dt
        out = stack.step(race.frenet[0], opponent, 0.5)
        race.step(out.u[None, :])
        assert not out.following
    assert stack.counters["follow_steps"] == 0


@pytest.mark.parametrize("recheck", [1, 2])
def test_follow_recheck_skips_the_passing_solve_between_examinations(tracks, recheck):
    """The Kentucky follow scenario above: with ``follow_recheck = 1`` every MIQP call while
    following solves the passing plan and the follow plan; with 2, every other call re-solves
    only the follow plan (one solve), and the ego keeps following without a collision."""
    track = tracks["Kentucky"]
    s0 = narrowest_approach(track)
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
        was_following = stack.following
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
    target = FollowTarget(rows, ego_s=100.0, step=8)  # recorded 2 steps (0.2 s) ago, the ego at s = 100 m
    ego_s, step = 110.0, 10  # the ego has advanced 10 m since
    pred = stack.predict(100.0, rows, np.array([0.2]))[0, 0] - 10.0
    opp_rel = np.array([[pred + 0.5, -3.0, 30.0], [pred - 0.4, 0.1, 30.0], [80.0, 0.0, 25.0]])
    found = stack.pass_or_follow._followed_rows
    assert found(ego_s, opp_rel, target, step).tolist() == [False, True, False]
    assert found(ego_s, opp_rel[[0, 2]], target, step) is None  # the car is gone (overtaken)
    assert found(ego_s, np.zeros((0, 3)), target, step) is None


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
    with_alongside = OvertakingStack(track).pass_or_follow.can_stay_behind(v, gaps, opp_s)
    without = OvertakingStack(track, StackConfig(follow_alongside=False)).pass_or_follow.can_stay_behind(
        v, gaps, opp_s)
    assert with_alongside.tolist() == [True, False, True]
    assert without.tolist() == [False, False, True]


def test_speed_cap_reaches_the_opponent_speed_follow_gap_behind(tracks):
    """The cap is sqrt(v_o^2 + 2 follow_decel (gap - follow_gap)): the opponent's speed at
    ``follow_gap`` behind it, higher further back; None when no car is followed."""
    stack = OvertakingStack(tracks["Monza"], StackConfig(pace_prediction=False))
    cfg = stack.config
    t = stack._mpc_t
    follow = stack.pass_or_follow
    assert follow.speed_cap(100.0, np.zeros_like(t), t, 0) is None
    v_o = 20.0
    follow.target = FollowTarget(np.array([[cfg.follow_gap, 0.0, v_o]]), ego_s=100.0, step=0)
    s_rel = v_o * t  # the ego keeps the opponent's speed, follow_gap behind
    np.testing.assert_allclose(follow.speed_cap(100.0, s_rel, t, 0), v_o, rtol=1e-12)
    further = follow.speed_cap(100.0, s_rel - 10.0, t, 0)
    np.testing.assert_allclose(further, np.sqrt(v_o ** 2 + 2.0 * cfg.follow_decel * 10.0), rtol=1e-12)


@pytest.mark.parametrize("rho, seed, gamma, until, overtakes", [
    # the ego ends up alongside a car as the left edge closes in at the last corner; holding
    # the pass squeezed it into that car at 110.5 s (with follow_alongside=False and
    # follow_release_slack=0.5; either fix alone avoids it)
    (0.65, 3252676551, 0.5, 112.0, 4),
    # at the same corner the follow decision flickered at every MIQP call (no hysteresis,
    # follow_release_slack = follow_slack), trading braking for pass attempts until a
    # collision at 119.6 s
    # Recorded on the Intel Xeon VM of the committed tables. On AVX2 without AVX-512 (an AMD EPYC,
    # Zen 3) the episode drifts apart and the same failure recurs: the follow decision flickers at
    # 117.3-118.1 s and the ego collides at 119.5 s.
    # The fix holds on one variant of this corner, not on every one; kept as a known failure there.
    pytest.param(0.3, 1531305125, 0.05, 121.0, 14, marks=pytest.mark.xfail(
        not _AVX512, reason="on AVX2 builds the episode drifts and the last-corner follow flicker recurs "
                            "(collision at 119.5 s)", strict=False)),
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
