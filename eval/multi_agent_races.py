"""Race the PettingZoo environment with one fixed gamma and report how much racing happens.

A quick look at the multi-agent race without the bookkeeping of ``eval/table.py --multi-agent``
(no CSV, one strategy, any race settings): each race is one seeded episode of
:func:`sofar_env.multi_agent.parallel_env` with its defaults (grid start, pace drawn per car in
``race.pace_range``), every car driving the same fixed gamma, until every car is terminated or
the duration is reached (:func:`sofar_agents.evaluation.multi_agent.run_race`). It prints the
table of ``eval/table.py --multi-agent`` per circuit and over all races: overtakes between
controlled cars per race (credited to the passer), races with a car-to-car collision, colliding,
off-track and stalled cars per race, success per car, car-seconds driven. Example::

    python eval/multi_agent_races.py --tracks LagunaSeca Monza Indianapolis Kentucky \\
        --seeds 0 1 2 --duration 100 --gamma 0.5 --cars 4

``--alongside-gap 6`` turns on the controllers' MIQP side lock for cars alongside
(``stack.miqp.alongside_gap``); ``--table-races 4 --duration 200`` races the fields of the multi-agent
table (its seeds) for an A/B against its committed rows. The races run on the executor
(:mod:`sofar_agents.executor`, in worker processes with ``--workers``); a race that fails or is lost with a worker
is logged and left out of the tables, and the script exits with status 1.
"""

from __future__ import annotations

import argparse
import functools
import logging
import math
import sys
import time

from sofar_agents.cli_types import gamma_value, int_at_least, nonneg_float, nonneg_int, positive_float, positive_int
from sofar_agents.evaluation.multi_agent import (
    RaceJob,
    RaceRunner,
    RaceTask,
    format_multi_agent_table,
    format_per_circuit,
    race_seed,
)
from sofar_agents.evaluation.protocol import Strategy
from sofar_agents.executor import execute, missing_summary
from sofar_env.constants import CIRCUITS

logger = logging.getLogger("multi_agent_races")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tracks", nargs="+", default=list(CIRCUITS), help="circuits (default: the four)")
    parser.add_argument("--seeds", nargs="+", type=nonneg_int, default=[0, 1, 2], help="reset seeds (default 0 1 2)")
    parser.add_argument("--duration", type=positive_float, default=100.0, help="race duration [s] (default 100)")
    parser.add_argument("--gamma", type=gamma_value, default=0.5, help="fixed gamma of every car (default 0.5)")
    parser.add_argument("--cars", type=int_at_least(2), default=4, help="controlled cars (default 4)")
    parser.add_argument("--pace-range", nargs=2, type=positive_float, default=None, metavar=("LO", "HI"),
                        help="race.pace_range of the cars' speed factors (default: the environment's)")
    parser.add_argument("--v2v", action="store_true",
                        help="race.v2v: the cars predict each other from their published MPC plans")
    parser.add_argument("--no-restart", action="store_true",
                        help="race.mpc_restart_slack = inf: the controllers' MPCs never restart from a cold guess")
    parser.add_argument("--lateral-rates", choices=("mpc", "all", "off"), default=None,
                        help="race.lateral_rates: what the controllers do with the other cars' lateral rates "
                             "(default: the environment's, mpc)")
    parser.add_argument("--heading-extent", type=nonneg_float, default=None, metavar="M",
                        help="race.heading_extent [m]: widen each car's barrier's lateral semi-axis with its "
                             "heading error (default: the environment's, 2.45; 0: off)")
    parser.add_argument("--alongside-gap", type=nonneg_float, default=0.0, metavar="M",
                        help="the controllers' MIQP side lock for cars alongside (stack.miqp.alongside_gap "
                             "[m]; default 0: off)")
    parser.add_argument("--table-races", type=positive_int, default=None, metavar="N",
                        help="instead of --seeds, the seeds of the first N races per circuit of "
                             "eval/table.py --multi-agent (base seed 0)")
    parser.add_argument("--workers", type=positive_int, default=1, help="races run in parallel processes (default 1)")
    parser.add_argument("--races", action="store_true", help="also print one line per race")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    overrides = {"pace_range": tuple(args.pace_range)} if args.pace_range else {}
    if args.v2v:
        overrides["v2v"] = True
    if args.no_restart:
        overrides["mpc_restart_slack"] = math.inf
    if args.lateral_rates:
        overrides["lateral_rates"] = args.lateral_rates
    if args.heading_extent is not None:
        overrides["heading_extent"] = args.heading_extent
    stack = {"miqp": {"alongside_gap": args.alongside_gap}} if args.alongside_gap else None
    strategy = Strategy.fixed(args.gamma)
    tasks = [RaceTask(track, strategy, seed, args.cars, args.duration) for track in args.tracks
             for seed in (args.seeds if args.table_races is None
                          else [race_seed(0, track, e) for e in range(args.table_races)])]
    t0 = time.perf_counter()
    job = RaceJob(None, functools.partial(RaceRunner, overrides, stack))
    stats = execute(tasks, job, workers=args.workers, progress=False)
    results = [job.results[t.key] for t in tasks if t.key in job.results]
    for r in results:
        logger.info("%s seed %d: %d overtakes, %d colliding, %d off track, %d stalled, pace %s",
                    r.track, r.seed, r.overtakes, r.collided, r.off_track, r.stalled, r.speed_factors)
    pace = ((f", pace_range {tuple(args.pace_range)}" if args.pace_range else "") + (", V2V" if args.v2v else "")
            + (f", alongside lock {args.alongside_gap:g} m" if args.alongside_gap else "")
            + (", no MPC restart" if args.no_restart else "")
            + (f", lateral rates {args.lateral_rates}" if args.lateral_rates else "")
            + (f", barrier heading extent {args.heading_extent:g} m" if args.heading_extent is not None else ""))
    seeds = (f"the first {args.table_races} races per circuit of the multi-agent table" if args.table_races
             else f"seeds {' '.join(map(str, args.seeds))}")
    print(f"{args.cars} cars, {args.duration:g} s, gamma {args.gamma:g}{pace}, {seeds} "
          f"({time.perf_counter() - t0:.0f} s)\n")
    print(format_per_circuit(results, [strategy.name], args.tracks))
    print()
    print(format_multi_agent_table(results, [strategy.name], {strategy.name: "**all**"}))
    if args.races:
        print("\n| circuit | seed | pace | overtakes | colliding | off track | stalled |")
        print("|---|---:|---|---:|---:|---:|---:|")
        for r in results:
            print(f"| {r.track} | {r.seed} | {r.speed_factors} | {r.overtakes} | {r.collided} | {r.off_track} | "
                  f"{r.stalled} |")
    missing = missing_summary(stats, unit="races")
    if missing:
        logger.error("incomplete: %s; the tables above leave them out", missing)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
