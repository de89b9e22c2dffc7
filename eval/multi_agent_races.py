"""Race the PettingZoo environment with a fixed gamma and report how much racing happens.

Each race is one seeded episode of :func:`sofar_env.multi_agent.parallel_env` with its defaults
(grid start, pace drawn per car in ``race.pace_range``), every car driving the same fixed gamma,
until every car is terminated or the duration is reached. Per circuit it prints a Markdown table of

* overtakes between controlled cars per race (the sum of every car's ``info["overtakes"]``, which
  credits the passer only),
* races with a car-to-car collision [%] and colliding cars per race,
* cars that left the track and cars that stalled, per race,
* car-seconds driven over the field's possible car-seconds [%],

and the same over all races. Example (the numbers of the issue's targets)::

    python eval/multi_agent_races.py --tracks LagunaSeca Monza Indianapolis Kentucky \\
        --seeds 0 1 2 --duration 100 --gamma 0.5 --cars 4
"""

from __future__ import annotations

import argparse
import logging
import sys
import time
from dataclasses import dataclass

import numpy as np

from sofar_env.constants import CIRCUITS, GAMMA_MAX, GAMMA_MIN

logger = logging.getLogger("multi_agent_races")


@dataclass(frozen=True)
class RaceResult:
    """Outcome of one race."""

    track: str
    seed: int
    overtakes: int
    """Overtakes between controlled cars (each credited to the passer)."""
    collided: int
    """Cars terminated by a collision with another car."""
    off_track: int
    """Cars terminated by leaving the track."""
    stalled: int
    """Cars terminated by the stall rule."""
    driven: float
    """Car-seconds driven over ``cars x duration`` [-]."""
    speed_factors: tuple[float, ...]


def run_race(track: str, seed: int, cars: int, duration: float, gamma: float,
             race_overrides: dict | None = None) -> RaceResult:
    """One seeded race with every car at ``gamma``; ``race_overrides`` go into the ``race`` config."""
    from sofar_env.multi_agent import parallel_env

    env = parallel_env(track, n_agents=cars, race={"duration": duration, **(race_overrides or {})},
                       timing_info=False)
    env.reset(seed=seed)
    action = np.array([gamma], np.float32)
    last: dict[str, dict] = {}
    while env.agents:
        _, _, terms, truncs, infos = env.step({a: action for a in env.agents})
        last.update(infos)
    race = env.race
    env.close()
    driven = sum(info["sim_time"] for info in last.values()) / (cars * duration)
    return RaceResult(
        track=track, seed=seed, overtakes=int(race.overtakes.sum()),
        collided=sum(bool(info["collision"]) for info in last.values()),
        off_track=sum(bool(info["off_track"]) for info in last.values()),
        stalled=sum(bool(info["stalled"]) for info in last.values()),
        driven=float(driven), speed_factors=tuple(round(f, 3) for f in env.speed_factors),
    )


def summary_row(name: str, results: list[RaceResult]) -> str:
    n = len(results)
    mean = lambda attr: sum(getattr(r, attr) for r in results) / n  # noqa: E731
    with_collision = 100.0 * sum(r.collided > 0 for r in results) / n
    return (f"| {name} | {n} | {mean('overtakes'):.2f} | {with_collision:.0f} | {mean('collided'):.2f} | "
            f"{mean('off_track'):.2f} | {mean('stalled'):.2f} | {100.0 * mean('driven'):.0f} |")


def table(results: list[RaceResult], tracks: list[str]) -> str:
    lines = ["| circuit | races | overtakes / race | races with a collision [%] | colliding cars / race | "
             "off-track cars / race | stalled cars / race | driven [%] |",
             "|---|---:|---:|---:|---:|---:|---:|---:|"]
    for track in tracks:
        lines.append(summary_row(track, [r for r in results if r.track == track]))
    lines.append(summary_row("**all**", results))
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tracks", nargs="+", default=list(CIRCUITS), help="circuits (default: the four)")
    parser.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2], help="reset seeds (default 0 1 2)")
    parser.add_argument("--duration", type=float, default=100.0, help="race duration [s] (default 100)")
    parser.add_argument("--gamma", type=float, default=0.5, help="fixed gamma of every car (default 0.5)")
    parser.add_argument("--cars", type=int, default=4, help="controlled cars (default 4)")
    parser.add_argument("--pace-range", nargs=2, type=float, default=None, metavar=("LO", "HI"),
                        help="race.pace_range of the cars' speed factors (default: the environment's)")
    parser.add_argument("--races", action="store_true", help="also print one line per race")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    if not GAMMA_MIN <= args.gamma <= GAMMA_MAX:
        parser.error(f"--gamma must lie in [{GAMMA_MIN}, {GAMMA_MAX}], got {args.gamma}")
    if args.duration <= 0 or args.cars < 2:
        parser.error("--duration must be > 0 and --cars >= 2")
    overrides = {"pace_range": tuple(args.pace_range)} if args.pace_range else {}
    results = []
    t0 = time.perf_counter()
    for track in args.tracks:
        for seed in args.seeds:
            r = run_race(track, seed, args.cars, args.duration, args.gamma, overrides)
            logger.info("%s seed %d: %d overtakes, %d colliding, %d off track, %d stalled, pace %s",
                        track, seed, r.overtakes, r.collided, r.off_track, r.stalled, r.speed_factors)
            results.append(r)
    pace = f", pace_range {tuple(args.pace_range)}" if args.pace_range else ""
    print(f"{args.cars} cars, {args.duration:g} s, gamma {args.gamma:g}{pace}, seeds {' '.join(map(str, args.seeds))} "
          f"({time.perf_counter() - t0:.0f} s)\n")
    print(table(results, args.tracks))
    if args.races:
        print("\n| circuit | seed | pace | overtakes | colliding | off track | stalled |")
        print("|---|---:|---|---:|---:|---:|---:|")
        for r in results:
            print(f"| {r.track} | {r.seed} | {', '.join(f'{f:.3f}' for f in r.speed_factors)} | {r.overtakes} | "
                  f"{r.collided} | {r.off_track} | {r.stalled} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
