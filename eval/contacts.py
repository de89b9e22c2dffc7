"""Replay the races of a multi-agent table that ended in a collision and show each first contact.

For every race of the per-race CSV of ``eval/table.py --multi-agent`` with a car-to-car collision and a
fixed-gamma strategy (the policies' rows need their checkpoints, which the CSV only names by hash), the
race is run again with the same seed and settings up to its first contact. One line per contact: when and
where (arc length of the first car), the two cars, their arc-length gap and lateral offset, their heading
errors to the track and their relative yaw, their speeds, and two barrier values of the first car against
the second at that moment (the velocity-aware ellipse of the MPC, :mod:`sofar_env.control.barrier`):
``h aligned``, the ellipse of cars aligned with the track, and ``h``, the first car's own barrier (with
the multi-car default ``race.heading_extent`` widened by both cars' rotation to the track).

``h >= 0`` at a contact means the ellipse called the two cars clear when their footprints touched: the
aligned ellipse contains the collision set of two cars *aligned* with the track, and a car turned by 0.4
rad is about 1.8 m wide across the track instead of 0.95 m. The replay runs the current code and its
defaults (``--heading-extent`` overrides the race's): a CSV written by an older version may not collide at
all any more, which the line then says. Example::

    python eval/contacts.py                                  # results/multi_agent/multi_agent_races.csv
    python eval/contacts.py --csv results/multi_agent/multi_agent_races.csv --out contacts.md
    python eval/contacts.py --heading-extent 0               # the cars' barrier without the heading widening
"""

from __future__ import annotations

import argparse
import math
import sys
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from sofar_agents.cli_types import nonneg_float
from sofar_agents.evaluation.files import write_text_atomic
from sofar_agents.evaluation.multi_agent import RaceResult, RaceTask, race_env, read_race_csv
from sofar_agents.evaluation.protocol import Strategy
from sofar_env.control.barrier import barrier

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
    h_aligned: float
    """Barrier value of the first car against the second, the ellipse of aligned cars [-]."""
    h: float
    """Barrier value of the first car against the second, the first car's own barrier (heading-aware in a
    multi-car race with ``race.heading_extent`` > 0) [-]."""


def first_contact(row: RaceResult, race_overrides: dict | None = None) -> Contact | None:
    """Replay the race of ``row`` (a fixed-gamma row) to its first car-to-car contact; None if it has none.
    ``race_overrides`` go into the race config (e.g. ``{"heading_extent": 0.0}``)."""
    gamma = float(row.strategy.split("=", 1)[1])
    env = race_env(RaceTask(row.track, Strategy.fixed(gamma), row.seed, row.cars, row.duration, row.stack,
                            row.scenario, row.opponents), race_overrides)
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
                gap = float(race.track.gap(fj[0], fi[0]))
                ego = np.array([0.0, fi[1], fi[2], fi[3], fi[4]])
                # the second car as the first one's barrier sees it: its speed along the track, its rotation
                other = np.array([gap, fj[1], fj[3] * math.cos(fj[2]) / (1.0 - kappa * fj[1]), math.sin(fj[2])])
                own = env.stacks[i].config.mpc.barrier
                h_aligned = barrier(ego, other[:3], replace(own, heading_extent=0.0))
                return Contact(float(race.time), (i, j), float(fi[0]), gap, float(fj[1] - fi[1]),
                               (float(fi[2]), float(fj[2])), (float(fi[3]), float(fj[3])), float(h_aligned),
                               float(barrier(ego, other, own)))
    finally:
        env.close()
    return None


def format_contacts(results: list[tuple[RaceResult, Contact | None]]) -> str:
    lines = ["| circuit | seed | strategy | t [s] | cars | s [m] | gap [m] | offset [m] | headings [rad] | "
             "relative yaw [rad] | speeds [m/s] | h aligned | h |",
             "|---|---:|---|---:|---|---:|---:|---:|---|---:|---|---:|---:|"]
    for row, c in results:
        if c is None:
            lines.append(f"| {row.track} | {row.seed} | {row.strategy} | no contact with this code | | | | | | | | | |")
            continue
        lines.append(f"| {row.track} | {row.seed} | {row.strategy} | {c.time:.1f} | {c.cars[0]}, {c.cars[1]} | "
                     f"{c.s:.0f} | {c.gap:.2f} | {c.offset:.2f} | {c.headings[0]:.2f}, {c.headings[1]:.2f} | "
                     f"{c.headings[1] - c.headings[0]:.2f} | {c.speeds[0]:.1f}, {c.speeds[1]:.1f} | "
                     f"{c.h_aligned:.2f} | {c.h:.2f} |")
    found = [c for _, c in results if c is not None]
    lines.append("")
    lines.append(f"{len(found)} contacts replayed; the barrier called the cars clear (h >= 0) at "
                 f"{sum(c.h_aligned >= 0.0 for c in found)} of them with the aligned ellipse and at "
                 f"{sum(c.h >= 0.0 for c in found)} with the cars' own barrier.")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--csv", default=str(DEFAULT_CSV), help="per-race CSV of eval/table.py --multi-agent")
    parser.add_argument("--out", default=None, help="also write the table to this Markdown file")
    parser.add_argument("--heading-extent", type=nonneg_float, default=None, metavar="M",
                        help="race.heading_extent of the replays [m] (default: the environment's)")
    args = parser.parse_args(argv)
    overrides = None if args.heading_extent is None else {"heading_extent": args.heading_extent}
    rows = [r for r in read_race_csv(args.csv) if r.collided > 0 and r.strategy.startswith("gamma=")]
    if not rows:
        print(f"no fixed-gamma race with a collision in {args.csv}")
        return 0
    table = format_contacts([(r, first_contact(r, overrides)) for r in rows])
    print(table)
    if args.out:
        write_text_atomic(args.out, table + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
