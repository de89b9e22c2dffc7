"""The barrier widened by the heading error in the single-car worlds (the candidate ``"sofar-11"``).

The scene is the paper world's one protocol collision of ``"sofar-6"`` and ``"sofar-10"`` (Laguna Seca, rho 0.1, the
episode's own seed, gamma 0.7): at 2.5 m/s, 3.4 m beside a car, the ego turns in towards it by 0.37 rad and sweeps
its front corner into it at 188.1 s while the ellipse of aligned cars still reads h = 0.01. With the lateral semi-axis
widened by half the car's length times |sin e| that state reads h = -0.43, and the MPC keeps away from it.
"""

from __future__ import annotations

import dataclasses

import gymnasium as gym
import numpy as np

import sofar_env  # noqa: F401  (registers the environments)
from sofar_env.configs.registry import stack_preset

SEED = 2546700349  # Laguna Seca, rho 0.1, an episode of Table I's protocol (base seed 0)


def _race(stack: str):
    env = gym.make("SOfAR-LagunaSeca-v0", stack=stack)
    env.reset(seed=SEED, options={"rho": 0.1})
    info, terminated, truncated = {}, False, False
    while not (terminated or truncated):
        _, _, terminated, truncated, info = env.step(np.array([0.7], np.float32))
    env.close()
    return info, terminated


def test_sofar_11_is_sofar_10_with_the_widened_barrier():
    a, b = stack_preset("sofar-10"), stack_preset("sofar-11")
    assert b.mpc.barrier.heading_extent == 2.45 and a.mpc.barrier.heading_extent == 0.0
    wide = dataclasses.replace(a.mpc.barrier, heading_extent=2.45)
    assert b == dataclasses.replace(a, mpc=dataclasses.replace(a.mpc, barrier=wide))


def test_the_aligned_ellipse_lets_the_turned_car_touch():
    info, terminated = _race("sofar-10")
    assert terminated and info["collision"] and 187.5 < info["sim_time"] < 189.0


def test_the_heading_widened_barrier_keeps_the_turned_car_away():
    info, terminated = _race("sofar-11")
    assert not terminated and info["is_success"] and not info["collision"] and not info["off_track"]
    assert info["sim_time"] >= 200.0 - 1e-6


def test_sofar_15_is_sofar_13_with_the_toward_widening():
    a, b = stack_preset("sofar-13"), stack_preset("sofar-15")
    assert a.mpc.barrier.heading_sides == "both" and b.mpc.barrier.heading_sides == "toward"
    toward = dataclasses.replace(a.mpc.barrier, heading_sides="toward")
    assert b == dataclasses.replace(a, mpc=dataclasses.replace(a.mpc, barrier=toward))


def test_the_toward_widening_keeps_the_turned_in_car_away():
    """The turn-in scene is a turn *towards* the car beside the ego: ``"sofar-15"`` keeps its widening there."""
    info, terminated = _race("sofar-15")
    assert not terminated and info["is_success"] and not info["collision"] and not info["off_track"]
