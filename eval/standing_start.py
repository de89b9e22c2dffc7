"""Can a controller drive off from rest near an edge? Place the ego at rest on an empty track and see.

Every placement (``--count`` arc lengths per circuit, both sides, each ``--clearances`` metres from the edge,
straight, wheels straight) is driven by every ``--stacks`` preset with a fixed gamma for ``--duration`` seconds;
a placement *drove off* when the car gained ``--min-distance`` metres without leaving the track
(:mod:`sofar_agents.evaluation.standing_start`). Writes ``standing_start.csv`` (one row per placement and
controller, with the configuration hash of its environment), ``standing_start.md`` and ``config.json`` to
``--out``. Example (the committed probe, about 3 minutes on one core)::

    python eval/standing_start.py --stacks sofar-1 sofar --out results/standing_start
"""

from __future__ import annotations

import argparse
import logging
import sys
import time
from pathlib import Path

from sofar_agents.cli_types import gamma_value, nonneg_float, positive_float, positive_int
from sofar_agents.evaluation.configs import episode_config, write_config_json
from sofar_agents.evaluation.standing_start import run_probe, write_probe
from sofar_env.constants import CIRCUITS
from sofar_env.scenarios import SCENARIOS
from sofar_env.stack.config import STACK_PRESETS

logger = logging.getLogger("standing_start")


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--tracks", nargs="+", choices=CIRCUITS, default=list(CIRCUITS), help="circuits (default: all)")
    p.add_argument("--stacks", nargs="+", choices=list(STACK_PRESETS), default=["sofar-1", "sofar"],
                   help="controller presets (default: sofar-1 sofar)")
    p.add_argument("--scenario", choices=list(SCENARIOS), default="paper", help="world (default paper)")
    p.add_argument("--count", type=positive_int, default=25, help="arc lengths per circuit (default 25)")
    p.add_argument("--clearances", nargs="+", type=nonneg_float, default=[0.5, 0.3, 0.15],
                   help="distances of the car's side from the edge [m] (default 0.5 0.3 0.15)")
    p.add_argument("--gamma", type=gamma_value, default=0.5, help="fixed gamma (default 0.5)")
    p.add_argument("--duration", type=positive_float, default=8.0, help="simulated seconds per run (default 8)")
    p.add_argument("--min-distance", type=positive_float, default=5.0,
                   help="arc length a run must gain to count as driving off [m] (default 5)")
    p.add_argument("--out", default="results/standing_start", help="output folder")
    p.add_argument("--log-level", default="INFO")
    return p.parse_args(argv)


def main(argv=None) -> int:
    args = parse_args(argv)
    logging.basicConfig(level=args.log_level.upper(), format="%(asctime)s %(message)s", datefmt="%H:%M:%S")
    out = Path(args.out)
    t0 = time.perf_counter()
    rows = run_probe(args.tracks, args.stacks, args.scenario, args.count, args.clearances, args.gamma,
                     args.duration, args.min_distance)
    wall = time.perf_counter() - t0
    write_config_json(out, [episode_config(stack, args.scenario) for stack in args.stacks])
    command = "python eval/standing_start.py " + " ".join(argv if argv is not None else sys.argv[1:])
    write_probe(out, rows, f"Standing starts near an edge ({args.scenario} world, gamma {args.gamma:g}, "
                f"{args.duration:g} s, drove off: {args.min_distance:g} m gained on the track)",
                f"{len(rows)} runs in {wall:.0f} s in one process. Command: `{command}`")
    logger.info("wrote %s and %s", out / "standing_start.csv", out / "standing_start.md")
    return 0


if __name__ == "__main__":
    sys.exit(main())
