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


def _race(circuit: str, seed: int, rho: float, **config):
    env = gym.make(f"SOfAR-{circuit}-v0", config={"race": {"duration": DURATION}, **config})
    env.reset(seed=seed, options={"rho": rho})
    info, terminated, truncated = {}, False, False
    while not (terminated or truncated):
        _, _, terminated, truncated, info = env.step(np.array([0.5], np.float32))
    return env, info, terminated


@pytest.mark.parametrize("circuit,seed", PARKED_RUNS)
def test_parked_cars_are_passed(circuit, seed):
    env, info, terminated = _race(circuit, seed, 0.0)
    progress = info["laps"] * env.unwrapped.track.length
    assert not terminated and info["is_success"] and not info["stalled"]
    assert not info["collision"] and not info["off_track"]
    assert progress > MIN_PROGRESS, f"{circuit}: only {progress:.0f} m in {DURATION} s"
    assert info["overtakes"] >= 4  # more than the field of four parked cars, passed at least once each
    assert info["parked_checks"] > 0


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
    ({"parked_speed": -0.5}, "parked_speed must be >= 0"),
    ({"parked_speed": float("nan")}, "parked_speed must be >= 0"),
    ({"parked_clearance": 0.0}, "parked_clearance must lie in (0, miqp.safe_lat"),
    ({"parked_clearance": 4.0}, "parked_clearance must lie in (0, miqp.safe_lat"),
    ({"parked_window": 9.0}, "parked_window must lie in (0, miqp.safe_lon"),
])
def test_bad_parked_settings_are_refused(changes, words):
    from sofar_env.stack import StackConfig

    with pytest.raises(ValueError) as err:
        StackConfig(**changes)
    assert words in str(err.value)
