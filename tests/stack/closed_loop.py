"""Closed-loop helpers of the stack tests: an empty race and a driving loop."""

from __future__ import annotations

import numpy as np

from sofar_env.opponents import OpponentConfig
from sofar_env.race import Race, RaceConfig
from sofar_env.stack import OvertakingStack

SETTLE = 5.0  # s


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


def narrowest_approach(track) -> float:
    """Arc length [m] 150 m before the narrowest point of ``track``."""
    s = np.linspace(0.0, track.length, 3000, endpoint=False)
    width = np.asarray(track.width_left(s) + track.width_right(s))
    return float(s[np.argmin(width)]) - 150.0
