"""Race a controller preset (default: the default) against a parked field (rho = 0); report who stops behind a car.

With ``rho = 0`` the four opponents stand on their lines. Each run is one seeded episode of
``SOfAR-<Circuit>-v0`` with a fixed gamma for ``--duration`` seconds. Per run it prints a Markdown
row: how the episode ended (``ok``: the duration reached, ``stalled``, ``collision``, ``off track``),
the simulated time, the distance driven, overtakes, the stack's counters of MIQP calls that
planned the pass of near-stationary opponents (``parked_checks``) and took it (``parked_passes``), the
longest standstill (slower than 1 m/s without interruption; a stop late in the race does not reach the
stall rule's 20 s), the nearest approach to an opponent (reference points) and the smallest barrier
value while an opponent is within 10 m (< 0: inside its barrier ellipse).
Example (the 24 runs of the parked-car check; ``--stack NAME`` races another controller preset)::

    python eval/parked_cars.py --tracks LagunaSeca Monza Indianapolis Kentucky --seeds 0 1 2 3 4 5
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass

import numpy as np

from sofar_agents.cli_types import gamma_value, nonneg_int, positive_float
from sofar_env.constants import CIRCUITS
from sofar_env.stack.config import STACK_PRESETS


@dataclass(frozen=True)
class ParkedRun:
    """Outcome of one race against a parked field."""

    track: str
    seed: int
    end: str
    """"ok", "stalled", "collision" or "off track"."""
    sim_time: float
    """Simulated time at the end [s]."""
    distance: float
    """Arc length driven [m]."""
    overtakes: int
    parked_checks: int
    parked_passes: int
    standstill: float
    """Longest time the ego was slower than 1 m/s without interruption [s] (the stall rule ends an
    episode at 20 s; a stop late in the race shows here)."""
    nearest: float
    """Smallest distance between the ego's and an opponent's reference points [m]."""
    min_barrier: float
    """Smallest barrier value h while an opponent was within 10 m (< 0: the ego was inside its barrier
    ellipse; far away the closing-speed ellipse of the start dominates h); inf if none came that close."""


def run(track: str, seed: int, duration: float, gamma: float, stack: dict | str | None = None) -> ParkedRun:
    """One seeded race against a parked field: of the default stack with the overrides ``stack`` (a dict), or of
    the controller preset named ``stack``."""
    import gymnasium as gym

    import sofar_env  # noqa: F401  (registers the environments)

    if isinstance(stack, str):
        env = gym.make(f"SOfAR-{track}-v0", config={"race": {"duration": duration}}, stack=stack)
    else:
        env = gym.make(f"SOfAR-{track}-v0", config={"race": {"duration": duration}, "stack": stack or {}})
    env.reset(seed=seed, options={"rho": 0.0})
    action = np.array([gamma], np.float32)
    info, terminated, truncated = {}, False, False
    slow, standstill, t_prev, nearest, min_h = 0.0, 0.0, 0.0, np.inf, np.inf
    while not (terminated or truncated):
        _, _, terminated, truncated, info = env.step(action)
        nearest = min(nearest, info["nearest_opponent_m"])
        if info["nearest_opponent_m"] < 10.0:
            min_h = min(min_h, info["min_barrier"])
        slow = slow + info["sim_time"] - t_prev if env.unwrapped.race.frenet[0, 3] < 1.0 else 0.0
        standstill, t_prev = max(standstill, slow), info["sim_time"]
    counters = env.unwrapped.stack.counters
    env.close()
    end = ("collision" if info["collision"] else "off track" if info["off_track"]
           else "stalled" if info["stalled"] else "ok" if info["is_success"] else "?")
    return ParkedRun(track, seed, end, float(info["sim_time"]),
                     float(info["laps"]) * float(env.unwrapped.track.length), int(info["overtakes"]),
                     int(counters["parked_checks"]), int(counters["parked_passes"]), standstill,
                     float(nearest), float(min_h))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tracks", nargs="+", default=list(CIRCUITS), choices=CIRCUITS)
    parser.add_argument("--seeds", nargs="+", type=nonneg_int, default=list(range(6)))
    parser.add_argument("--duration", type=positive_float, default=60.0, help="race duration [s]")
    parser.add_argument("--gamma", type=gamma_value, default=0.5, help="fixed barrier decay")
    parser.add_argument("--stack", default="sofar", choices=STACK_PRESETS,
                        help=f"controller preset, one of {', '.join(STACK_PRESETS)} (default sofar)")
    args = parser.parse_args(argv)
    print("| circuit | seed | end | time [s] | driven [m] | overtakes | parked checks | parked passes "
          "| standstill [s] | nearest [m] | min h within 10 m |")
    print("|---|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    runs = []
    for track in args.tracks:
        for seed in args.seeds:
            r = run(track, seed, args.duration, args.gamma, args.stack)
            runs.append(r)
            print(f"| {r.track} | {r.seed} | {r.end} | {r.sim_time:.1f} | {r.distance:.0f} | {r.overtakes} "
                  f"| {r.parked_checks} | {r.parked_passes} | {r.standstill:.1f} | {r.nearest:.1f} "
                  f"| {r.min_barrier:.2f} |", flush=True)
    ends = [r.end for r in runs]
    stopped = sum(r.standstill >= 5.0 for r in runs)
    print(f"\n{len(runs)} runs: " + ", ".join(f"{ends.count(e)} {e}" for e in sorted(set(ends)))
          + f"; {stopped} with a standstill of 5 s or more")
    return 0


if __name__ == "__main__":
    sys.exit(main())
