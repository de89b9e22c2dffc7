"""Could a gamma chosen during a race have saved it? Counterfactual gamma switches before each failure.

    python eval/interventions.py results/paper_stack/table1_episodes.csv --gamma 0.05 --workers 2 \
        --out results/paper_stack/interventions
    python eval/interventions.py CSV --quick          # 2 failed episodes, 2 switches + the placebos
    python eval/interventions.py results/paper_stack/interventions/interventions.csv --report   # re-make the report

For every failed episode of the fixed gamma ``--gamma`` in the given per-episode CSVs (Table I runs of
`eval/table.py`), the episode is replayed to find its failure step, then replayed once per
intervention: gamma switched to each of ``--gammas`` from each of ``--windows`` seconds before the
failure to ``--hold`` seconds after it. Two placebos use the longest window: a tiny change of gamma
(``--placebo-delta``) and the strongest switch ``--placebo-lead`` seconds earlier. Rescues beyond the
placebos' are what a within-race gamma could gain; rescues at their rate are re-drawn outcomes.
The report ends with each timely switch of the placebo's window against the displaced placebo, paired on
the failures both were run on (exact McNemar test). Writes ``interventions.csv`` (one row per replay) and
``interventions.md`` to ``--out``; ``--report`` re-makes ``interventions.md`` from an ``interventions.csv``
(in its folder, or ``--out``) without running an episode. The replays run on the executor with Table I's
behaviour: rerunning the same command resumes (the episodes whose replays ``interventions.csv`` holds, under the
same configuration hash, are skipped), and a run that leaves episodes out (failed, or lost with a worker process
that died) says how many and exits with status 1. The logic is in sofar_agents.evaluation.interventions.
"""

from __future__ import annotations

import argparse
import csv
import logging
import sys
import time
from pathlib import Path

from sofar_agents import evaluation as ev
from sofar_agents.cli_types import finite_float, gamma_value, nonneg_float, positive_int
from sofar_agents.evaluation import interventions as iv

logger = logging.getLogger("interventions")


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("csv", nargs="+", help="per-episode CSVs of Table I (table1_episodes.csv); with --report, "
                                          "one interventions.csv")
    p.add_argument("--report", action="store_true",
                   help="re-make the report of an interventions.csv (no episode is run)")
    p.add_argument("--gamma", type=gamma_value, default=0.05, help="the fixed gamma whose failures are replayed")
    p.add_argument("--gammas", type=gamma_value, nargs="+", default=[0.15, 0.3, 0.6], help="gammas inside the window")
    p.add_argument("--windows", type=nonneg_float, nargs="+", default=[1.0, 2.0, 4.0],
                   help="how long before the failure the window opens [s]")
    p.add_argument("--hold", type=nonneg_float, default=2.0,
                   help="how long after the failure the window stays open [s]")
    p.add_argument("--placebo-delta", type=finite_float, default=0.01, help="gamma change of the tiny-change placebo")
    p.add_argument("--placebo-lead", type=nonneg_float, default=20.0, help="shift of the displaced placebo [s]")
    p.add_argument("--limit", type=positive_int, default=None, help="at most this many failed episodes per CSV")
    p.add_argument("--workers", type=positive_int, default=1, help="worker processes")
    p.add_argument("--quick", action="store_true",
                   help="a first look: 2 failed episodes per CSV, gammas 0.6, windows 2 and 4 s (explicit options win)")
    p.add_argument("--out", default=None, help="output folder (default: results/interventions; with --report, the "
                                               "CSV's folder)")
    args = p.parse_args(argv)
    if args.quick:
        given = {a.split("=")[0] for a in (argv if argv is not None else sys.argv[1:])}
        if "--limit" not in given:
            args.limit = 2
        if "--gammas" not in given:
            args.gammas = [0.6]
        if "--windows" not in given:
            args.windows = [2.0, 4.0]
    return args


def report(args) -> int:
    """``--report``: the Markdown of an existing interventions.csv."""
    try:
        if len(args.csv) != 1:
            raise ValueError(f"--report takes one interventions.csv, got {len(args.csv)} files")
        path = Path(args.csv[0])
        if not path.is_file():
            raise ValueError(f"no such CSV: {path}")
        with open(path, newline="") as f:
            reader = csv.DictReader(f)
            missing = [c for c in iv.INTERVENTION_COLUMNS if c not in (reader.fieldnames or []) and c not in
                       iv.ADDED_COLUMNS]
            if missing:
                raise ValueError(f"{path} is not an interventions.csv (missing columns {missing})")
            results = iv.results_from_rows(list(reader))
        gammas = {r.base_gamma for r in results}
        if len(gammas) != 1:
            raise ValueError(f"{path} mixes base gammas {sorted(gammas)}; one per file")
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    out = Path(args.out) if args.out else path.parent
    text = iv.format_interventions(iv.summarize_interventions(results), gammas.pop(), iv.placebo_comparisons(results))
    old = out / "interventions.md"
    if old.is_file():  # keep the run's own last paragraph (replays, wall time, command)
        tail = old.read_text().split("\n\n")[-1]
        if " replays, " in tail:
            text += "\n" + tail
    ev.write_markdown(out / "interventions.md", text)
    print(text)
    return 0


def main(argv=None) -> int:
    args = parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    if args.report:
        return report(args)
    if args.out is None:
        args.out = "results/interventions"
    try:
        interventions = iv.default_interventions(args.gamma, args.gammas, args.windows, args.hold,
                                                 args.placebo_delta, args.placebo_lead)
        episodes = []
        for name, rows in ev.read_seed_sets(args.csv).items():
            found = iv.failed_episodes(rows, args.gamma, args.limit)
            logger.info("%s: %d failed episodes of gamma %.2f", name, len(found), args.gamma)
            episodes += found
        if not episodes:
            raise ValueError(f"no failed episode of gamma {args.gamma:.2f} in {', '.join(args.csv)}")
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    t0 = time.perf_counter()
    out = Path(args.out)
    try:
        results, stats = iv.replay_interventions(episodes, interventions, out / "interventions.csv",
                                                 workers=args.workers)
    except ValueError as exc:  # an interventions.csv of another kind in --out
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"\ninterrupted: finished replays are in {out}; rerun the same command to resume", file=sys.stderr)
        return 130
    wall = time.perf_counter() - t0
    text = iv.format_interventions(iv.summarize_interventions(results), args.gamma, iv.placebo_comparisons(results))
    incomplete = ev.incomplete_message(stats, args.out, unit="failed episodes")
    if incomplete:
        text += (f"\n**Incomplete:** {stats.unfinished} of {stats.requested} failed episodes are missing; rerun the "
                 "same command.\n")
    replays = len(results)
    steps = sum(r.steps for r in results)
    text += (f"\n{replays} replays, {steps:,} env steps, {wall:.0f} s on {args.workers} worker(s). "
             f"Command: `python eval/interventions.py {' '.join(args.csv)} --gamma {args.gamma:g} "
             f"--gammas {' '.join(f'{g:g}' for g in args.gammas)} --windows {' '.join(f'{x:g}' for x in args.windows)} "
             f"--hold {args.hold:g} --placebo-delta {args.placebo_delta:g} --placebo-lead {args.placebo_lead:g}"
             + (f" --limit {args.limit}" if args.limit else "") + f" --workers {args.workers} --out {args.out}`\n")
    ev.write_markdown(out / "interventions.md", text)
    print(text)
    if incomplete:
        logger.error(incomplete)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
