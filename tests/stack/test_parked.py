"""Passing a parked car (sofar_env.stack.follow, ``StackConfig.parked_pass``).

With ``rho = 0`` the opponents stand on their lines. The default controller used to follow
such a car and stop behind it for the rest of the race; it now passes it when its passing
plan can keep the barrier's lateral semi-axis from it, and never uses that logic against
a moving field.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import sofar_env  # noqa: F401  (registers the environments)

# (circuit, seed): runs in which the ego used to stop behind a parked car within 20 s for good
PARKED_RUNS = [("LagunaSeca", 0), ("Monza", 1)]
DURATION = 50.0  # s
MIN_PROGRESS = 1000.0
"""[m] in 50 s: 20 m/s on average. Stopped behind the parked car, the ego covered 244 m (Laguna
Seca) and 640 m (Monza) in the whole race."""


def _race(circuit: str, seed: int, rho: float, stack: str = "sofar", **config):
    env = gym.make(f"SOfAR-{circuit}-v0", config={"race": {"duration": DURATION}, **config}, stack=stack)
    env.reset(seed=seed, options={"rho": rho})
    info, terminated, truncated = {}, False, False
    while not (terminated or truncated):
        _, _, terminated, truncated, info = env.step(np.array([0.5], np.float32))
    return env, info, terminated


PARKED_CASES = [
    *[("sofar-6", circuit, seed) for circuit, seed in PARKED_RUNS],
    pytest.param("sofar-13", "LagunaSeca", 0, marks=pytest.mark.xfail(strict=True, reason=(
        "known defect of \"sofar-13\", the default before \"sofar-17\": after three passes the ego stands behind "
        "a parked car and stalls at 36 s, where \"sofar-6\" passes all four; the barrier widened by the heading "
        "error (from \"sofar-11\" on) alone makes the difference, both ways (docs/decisions/default-controller.md)"))),
    ("sofar", "LagunaSeca", 0),  # the default "sofar-17" widens the barrier only by the turns that bring it closer
    ("sofar", "Monza", 1),
    ("sofar-15", "LagunaSeca", 0),  # the candidate that brought that barrier
]


@pytest.mark.parametrize("stack,circuit,seed", PARKED_CASES)
def test_parked_cars_are_passed(stack, circuit, seed):
    env, info, terminated = _race(circuit, seed, 0.0, stack=stack)
    progress = info["laps"] * env.unwrapped.track.length
    assert not terminated and info["is_success"] and not info["stalled"]
    assert not info["collision"] and not info["off_track"]
    assert progress > MIN_PROGRESS, f"{circuit}: only {progress:.0f} m in {DURATION} s"
    assert info["overtakes"] >= 4  # more than the field of four parked cars, passed at least once each
    assert info["parked_checks"] > 0


def _longest_standstill(circuit: str, seed: int, duration: float, stack: str = "sofar"):
    """Race a parked field; the info at the end and the longest time [s] the ego was slower than 1 m/s."""
    env = gym.make(f"SOfAR-{circuit}-v0", config={"race": {"duration": duration}}, stack=stack)
    env.reset(seed=seed, options={"rho": 0.0})
    info, terminated, truncated, slow, standstill, t_prev = {}, False, False, 0.0, 0.0, 0.0
    while not (terminated or truncated):
        _, _, terminated, truncated, info = env.step(np.array([0.5], np.float32))
        slow = slow + info["sim_time"] - t_prev if env.unwrapped.race.frenet[0, 3] < 1.0 else 0.0
        standstill, t_prev = max(standstill, slow), info["sim_time"]
    return env, info, terminated, standstill


CHICANE_STACKS = [
    "sofar-1",
    pytest.param("sofar", marks=pytest.mark.xfail(strict=True, reason=(
        "known defect of the default \"sofar-17\" (and of \"sofar-13\", \"sofar-6\", \"sofar-4\"): below 10 m/s "
        "its slow end rows keep room to turn back that the "
        "converging edges of the chicane do not leave beside the parked car, and it stands behind it for 14.3 s "
        "(\"sofar-13\": from 45.7 s on; docs/decisions/default-controller.md)"))),
]


@pytest.mark.parametrize("stack", CHICANE_STACKS)
def test_a_car_parked_where_the_raceline_crosses_a_chicane_is_passed(stack):
    """Monza, seed 5: a car parked on the raceline at the first chicane's entry (s = 611 m), where the
    raceline crosses the track and both edges converge on it by up to 0.5 m per metre. There is room
    beside it (4.3 m on either side), but the ego used to stop 11.5 m behind it, from 43 s on, for the
    rest of the race: a box window asked for the full clearance up to a node spacing beyond the cars'
    overlap, where the barrier needs far less, and the MPC's bound against the converging edge was
    tightened by the heading error to the raceline that following that edge takes."""
    env, info, terminated, standstill = _longest_standstill("Monza", 5, 60.0, stack)
    assert not terminated and info["is_success"] and not info["collision"] and not info["off_track"]
    assert standstill < 2.0, f"stood still for {standstill:.1f} s"
    assert info["laps"] * env.unwrapped.track.length > 1900.0  # past the chicane (1724 m when stopped)


def test_a_side_switch_the_held_pass_leaves_no_room_for_is_made_slowly():
    """Indianapolis, seed 5: two parked cars 60 m apart, the first passable on the right only (where the
    ego already is) and the second on the left only. At 30 m/s the switch does not fit between them,
    and once the ego can no longer stop behind the first car, that pass is held; the second car is then
    followed (the ego slows down while passing the first) until the switch fits. Without that, the ego
    ended at the second car's barrier on the wrong side of it and stalled there."""
    _, info, terminated, standstill = _longest_standstill("Indianapolis", 5, 30.0)
    assert not terminated and info["is_success"] and not info["collision"] and not info["off_track"]
    assert standstill < 2.0, f"stood still for {standstill:.1f} s"


def test_without_parked_pass_the_ego_stops_behind_the_parked_car():
    """The same Laguna Seca run with the parked pass off: the old behaviour, stuck and stalled."""
    _, info, terminated = _race("LagunaSeca", 0, 0.0, stack={"parked_pass": False})
    assert terminated and info["stalled"] and not info["is_success"]
    assert info["parked_checks"] == 0


def test_a_moving_field_never_uses_the_parked_pass():
    """Table I's slowest field (rho = 0.1) on Monza, whose slowest corner gives the slowest opponents
    (1.75 m/s, above ``parked_speed`` = 1 m/s): the parked logic is never even tried."""
    _, info, _ = _race("Monza", 1, 0.1)
    assert info["parked_checks"] == 0 and not info["stalled"]


@pytest.mark.parametrize("changes,words", [
    ({"parked_speed": -0.5}, "parked_speed must be a finite number >= 0"),
    ({"parked_speed": float("nan")}, "parked_speed must be a finite number >= 0"),
    ({"parked_clearance": 0.0}, "parked_clearance must lie in (0, miqp.safe_lat"),
    ({"parked_clearance": 4.0}, "parked_clearance must lie in (0, miqp.safe_lat"),
    ({"parked_window": 9.0}, "parked_window must lie in (0, miqp.safe_lon"),
])
def test_bad_parked_settings_are_refused(changes, words):
    from sofar_env.stack import StackConfig

    with pytest.raises(ValueError) as err:
        StackConfig(**changes)
    assert words in str(err.value)
