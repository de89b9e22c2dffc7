"""Is a stall the optimum of the controller's problem? Probe the stalled episodes of a per-episode CSV.

    python eval/stall_probe.py results/interactive_dense/stall_rate_seed11100/sofar_6/table1_episodes.csv \
        --out results/interactive_dense/stall_rate_seed11100/sofar_6/stalls

Every stalled fixed-gamma episode of the CSVs is replayed once and probed ``--before`` seconds before it ended
(the stall rule ends an episode after 20 s below 1 m/s: by default 17, 10 and 3 s before, early, middle and late
in the stall), and the MPC's problem at that step is solved to convergence with IPOPT at its own horizon and at the
longer ``--horizons``, from the MPC's warm start and from standing and creeping guesses; each stall gets a verdict
per probed step (``drives``, ``rti``, ``horizon`` or ``stands``). Writes <out>/horizon_probe.md. One process; the
logic is in sofar_agents.evaluation.stall_probe.
"""

from __future__ import annotations

import argparse
import logging
import shlex
import sys
import time
from pathlib import Path

from sofar_agents import evaluation as ev
from sofar_agents.cli_types import positive_float, positive_int
from sofar_agents.evaluation.files import write_text_atomic
from sofar_agents.evaluation.stall_probe import probe_markdown, probe_stall
from sofar_agents.evaluation.stall_rows import stalled_tasks

logger = logging.getLogger("stall_probe")


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("csvs", nargs="+", metavar="CSV", help="per-episode CSVs (table1_episodes.csv, eval/table.py)")
    p.add_argument("--out", required=True, help="output folder (horizon_probe.md)")
    p.add_argument("--before", nargs="+", type=positive_float, default=[17.0, 10.0, 3.0],
                   help="probe these many seconds before the episode ended (default 17 10 3)")
    p.add_argument("--horizons", nargs="+", type=positive_int, default=[20, 40, 80],
                   help="horizons [stages] to solve at, besides the MPC's own (default 20 40 80)")
    p.add_argument("--limit", type=positive_int, default=None, help="at most this many stalls")
    p.add_argument("--log-level", default="INFO")
    args = p.parse_args(argv)
    if min(args.horizons) < 2:
        p.error(f"argument --horizons: a horizon must be at least 2 stages, got {min(args.horizons)}")
    return args


def main(argv=None) -> int:
    args = parse_args(argv)
    logging.basicConfig(level=args.log_level.upper(), format="%(levelname)s %(name)s: %(message)s")
    try:
        rows = [r for path in args.csvs for r in ev.read_episode_csv(path)]
    except (OSError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    stalled = [r for r in rows if r.get("stalled") and str(r["strategy"]).startswith("gamma=")]
    tasks = stalled_tasks(stalled)[: args.limit]
    if not tasks:
        print("error: no stalled fixed-gamma episode in the CSVs", file=sys.stderr)
        return 2
    probes = []
    t0 = time.perf_counter()
    for task, row in zip(tasks, stalled):
        times = [float(row["sim_time"]) - b for b in args.before]
        try:
            found = probe_stall(task, times, args.horizons)
        except ValueError as exc:
            logger.error("%s %s seed %d gamma %g: %s", task.stack, task.track, task.seed, task.strategy.gamma, exc)
            continue
        for probe in found:
            logger.info("%s rho %g seed %d gamma %g at %.1f s: %s", task.track, task.rho, task.seed,
                        task.strategy.gamma, probe.at, probe.verdict)
        probes.append(found)
    command = "python eval/stall_probe.py " + " ".join(shlex.quote(a) for a in (argv or sys.argv[1:]))
    md = probe_markdown([p for found in probes for p in found], command)
    md += f"\n{len(probes)} stalls probed in {time.perf_counter() - t0:.0f} s (one process).\n"
    path = write_text_atomic(Path(args.out) / "horizon_probe.md", md)
    print(md)
    print(f"Wrote {path}")
    return 0 if len(probes) == len(tasks) else 1


if __name__ == "__main__":
    sys.exit(main())
