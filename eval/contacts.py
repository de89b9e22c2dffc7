"""Replay the races of a multi-agent table that ended in a collision and show each first contact.

For every race of the per-race CSV of ``eval/table.py --multi-agent`` with a car-to-car collision and a
fixed-gamma strategy (the policies' rows need their checkpoints, which the CSV only names by hash), the
race is run again with the same seed and settings up to its first contact. One line per contact: when and
where (arc length of the first car), the two cars, their arc-length gap and lateral offset, their heading
errors to the track and their relative yaw, their speeds, and the barrier value h of the first car against
the second at that moment (the velocity-aware ellipse of the MPC, :mod:`sofar_env.control.barrier`).

``h >= 0`` at a contact means the ellipse called the two cars clear when their footprints touched: the
ellipse contains the collision set of two cars *aligned* with the track, and a car turned by 0.4 rad is
about 1.8 m wide across the track instead of 0.95 m. The replay runs the current code: a CSV written by
an older version may not collide at all any more, which the line then says. Example::

    python eval/contacts.py                                  # results/multi_agent/multi_agent_races.csv
    python eval/contacts.py --csv results/multi_agent/multi_agent_races.csv --out contacts.md
"""

from __future__ import annotations

import argparse
import math
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from sofar_agents.evaluation.multi_agent import RaceResult, RaceTask, race_env, read_race_csv
from sofar_agents.evaluation.protocol import Strategy
from sofar_env.control.barrier import min_barrier

DEFAULT_CSV = Path(__file__).resolve().parents[1] / "results" / "multi_agent" / "multi_agent_races.csv"


@dataclass(frozen=True)
class Contact:
    """The first car-to-car contact of a replayed race."""

    time: float
    """Race time [s]."""
    cars: tuple[int, int]
    s: float
    """Arc length of the first car [m]."""
    gap: float
    """Arc-length gap from the first car to the second [m]."""
    offset: float
    """Lateral offset of the second car from the first [m]."""
    headings: tuple[float, float]
    """Heading errors to the track [rad]."""
    speeds: tuple[float, float]
    """Speeds [m/s]."""
    h: float
    """Barrier value of the first car against the second [-]."""


def first_contact(row: RaceResult) -> Contact | None:
    """Replay the race of ``row`` (a fixed-gamma row) to its first car-to-car contact; None if it has none."""
    gamma = float(row.strategy.split("=", 1)[1])
    env = race_env(RaceTask(row.track, Strategy.fixed(gamma), row.seed, row.cars, row.duration, row.stack,
                            row.scenario, row.opponents))
    env.reset(seed=int(row.seed))
    race, action = env.race, np.array([gamma], np.float32)
    try:
        while env.agents:
            _, _, _, _, infos = env.step({a: action for a in env.agents})
            hit = sorted(env.possible_agents.index(a) for a, info in infos.items() if info["collision"])
            if len(hit) >= 2:
                i, j = hit[:2]
                fi, fj = race.frenet[i].copy(), race.frenet[j].copy()
                kappa = float(race.track.curvature(fj[0]))
                row_j = np.array([[fj[0], fj[1], fj[3] * math.cos(fj[2]) / (1.0 - kappa * fj[1])]])
                h = min_barrier(race.track, fi, row_j, env.config.stack.mpc.barrier)
                return Contact(float(race.time), (i, j), float(fi[0]), float(race.track.gap(fj[0], fi[0])),
                               float(fj[1] - fi[1]), (float(fi[2]), float(fj[2])), (float(fi[3]), float(fj[3])),
                               float(h))
    finally:
        env.close()
    return None


def format_contacts(results: list[tuple[RaceResult, Contact | None]]) -> str:
    lines = ["| circuit | seed | strategy | t [s] | cars | s [m] | gap [m] | offset [m] | headings [rad] | "
             "relative yaw [rad] | speeds [m/s] | h |",
             "|---|---:|---|---:|---|---:|---:|---:|---|---:|---|---:|"]
    for row, c in results:
        if c is None:
            lines.append(f"| {row.track} | {row.seed} | {row.strategy} | no contact with this code | | | | | | | | |")
            continue
        lines.append(f"| {row.track} | {row.seed} | {row.strategy} | {c.time:.1f} | {c.cars[0]}, {c.cars[1]} | "
                     f"{c.s:.0f} | {c.gap:.2f} | {c.offset:.2f} | {c.headings[0]:.2f}, {c.headings[1]:.2f} | "
                     f"{c.headings[1] - c.headings[0]:.2f} | {c.speeds[0]:.1f}, {c.speeds[1]:.1f} | {c.h:.2f} |")
    found = [c for _, c in results if c is not None]
    clear = sum(c.h >= 0.0 for c in found)
    lines.append("")
    lines.append(f"{len(found)} contacts replayed; at {clear} of them the barrier called the cars clear (h >= 0).")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--csv", default=str(DEFAULT_CSV), help="per-race CSV of eval/table.py --multi-agent")
    parser.add_argument("--out", default=None, help="also write the table to this Markdown file")
    args = parser.parse_args(argv)
    rows = [r for r in read_race_csv(args.csv) if r.collided > 0 and r.strategy.startswith("gamma=")]
    if not rows:
        print(f"no fixed-gamma race with a collision in {args.csv}")
        return 0
    table = format_contacts([(r, first_contact(r)) for r in rows])
    print(table)
    if args.out:
        Path(args.out).write_text(table + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
