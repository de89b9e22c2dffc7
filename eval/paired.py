"""Is strategy A's success rate really different from B's? Paired exact tests on Table I episodes.

    python eval/paired.py results/dynamic/pasta_dynamic_low/seed0/table1_episodes.csv \
        results/dynamic/pasta_dynamic_low/seed21/table1_episodes.csv --a adaptive --b gamma=0.05
    python eval/paired.py results/paper_stack/table1_episodes.csv results/paper_stack/seed21/table1_episodes.csv \
        --a adaptive --out results/paper_stack/paired.md

    python eval/paired.py results/interactive_dense/end_rows/*/table1_episodes.csv --by-stack \
        --a sofar-recover:gamma=0.05 --b sofar:gamma=0.05
    python eval/paired.py --before-after results/sofar-1/table1/table1_episodes.csv results/table1_episodes.csv
    python eval/paired.py --pareto results/dynamic/morl_sofar4/pareto_episodes.csv --b gamma=0.50 \
        --out results/dynamic/morl_sofar4/paired.md

Each CSV is one seed set (from `eval/table.py`); the sets are pooled with their episodes kept apart.
Strategy names are those of the CSV's `strategy` column (`adaptive`, `gamma=0.05`, ...). Without
`--b`, A is compared with every other strategy. For each pair: the paired episodes, both success
rates, the difference with its standard error, the episodes only one of them wins, and the two-sided
exact McNemar p-value. With `--by-stack` the strategies are named `<stack>:<strategy>`, to compare
controller presets (`eval/table.py --stack`) run on the same episodes; the CSVs are then pooled into
one set, episodes matched by circuit, pace ratio and seed (one CSV per preset and seed set). No episode
is run. The logic is in sofar_agents.evaluation.paired.

With `--before-after BEFORE AFTER` the two CSVs are one seed set run by two controllers: per strategy and for
all fixed gammas together, success with the paired test and collisions, off-tracks, stalls and overtakes per
hour, each as before -> after (sofar_agents.evaluation.before_after). With `--races` as well, the two CSVs are
per-race CSVs of the multi-agent table (`multi_agent_races.csv`) of the same races: per strategy, success per car,
races with a collision (exact McNemar on the races that have one on one side only), off-track and stalled cars,
overtakes per race and the plans in force that were the passing planner's fallback
(sofar_agents.evaluation.races_before_after):

    python eval/paired.py --before-after --races results/multi_agent/multi_agent_races.csv \
        results/multi_agent/candidate_sofar_14/multi_agent_races.csv

With `--pareto CSV [CSV ...]` (a `pareto_episodes.csv` of `eval/pareto.py`, or several seed sets of one
front, their episodes pooled) every point that is not a fixed gamma (a
policy at each preference, an SB3 policy) is compared with the fixed gamma nearest to its mean gamma and with the
best fixed gamma (and with the strategies of `--b`, if given): success by the exact McNemar test, overtakes per
hour by the Wilcoxon signed-rank test (sofar_agents.evaluation.pareto_paired).

With `--target-power N` (CSVs of one or more seed sets, pooled): for each fixed gamma, how often it would itself
come within `--margin` (default 0.02) of the best fixed gamma's success on a fresh set of N episodes, resampled
with their outcomes under every fixed gamma kept together (sofar_agents.evaluation.target_power): the chance a
policy that *is* that fixed gamma has to meet the safety-first target of a Pareto front:

    python eval/paired.py --target-power 40 \
        results/interactive_dense/morl_sofar17/train_seed91/seed21500/pareto_episodes.csv \
        results/interactive_dense/morl_sofar17/train_seed91/seed22500/pareto_episodes.csv
"""

from __future__ import annotations

import argparse
import sys

from sofar_agents import evaluation as ev
from sofar_agents.cli_types import float_in, positive_int


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("csv", nargs="+", help="per-episode CSVs (table1_episodes.csv), one per seed set; with "
                                          "--before-after: the before CSV, then the after CSV")
    p.add_argument("--a", default="adaptive", help="the strategy under test (default: adaptive)")
    p.add_argument("--b", nargs="+", default=None, help="strategies to compare it with (default: every other one)")
    p.add_argument("--by-stack", action="store_true",
                   help="name strategies <stack>:<strategy> (e.g. sofar:gamma=0.05) and pool the CSVs, to compare "
                        "controller presets run on the same episodes")
    p.add_argument("--before-after", action="store_true",
                   help="compare two CSVs of the same episodes run by two controllers, on every outcome")
    p.add_argument("--races", action="store_true",
                   help="with --before-after: the two CSVs are per-race CSVs of the multi-agent table")
    p.add_argument("--pareto", action="store_true",
                   help="pareto_episodes.csv files (one front's seed sets, pooled): each policy point against the "
                        "nearest and the best fixed gamma")
    p.add_argument("--target-power", type=positive_int, default=None, metavar="N",
                   help="per fixed gamma: how often it is within --margin of the best fixed gamma's success on N "
                        "resampled episodes of the pooled CSVs")
    p.add_argument("--margin", type=float_in(0.0, 1.0), default=0.02,
                   help="with --target-power: the target's margin, a share in [0, 1] (default 0.02, two points)")
    p.add_argument("--out", default=None, help="also write the Markdown table to this file")
    return p.parse_args(argv)


def main(argv=None) -> int:
    args = parse_args(argv)
    mode = (_before_after if args.before_after else _pareto if args.pareto
            else _target_power if args.target_power is not None else _paired)
    if args.races and not args.before_after:
        print("error: --races goes with --before-after", file=sys.stderr)
        return 2
    if args.target_power is not None and (args.before_after or args.pareto):
        print("error: --target-power goes with neither --before-after nor --pareto", file=sys.stderr)
        return 2
    try:
        text = mode(args)
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(text, end="")
    if args.out:
        ev.write_markdown(args.out, text)
    return 0


def _paired(args: argparse.Namespace) -> str:
    sets = ev.read_seed_sets(args.csv)
    if args.by_stack:  # one set: the presets' CSVs hold the same episodes, matched by their seeds
        sets = ev.label_by_stack({" + ".join(sets): [r for rows in sets.values() for r in rows]})
    rows = ev.compare_to(sets, args.a, args.b)
    return f"Paired comparisons over {', '.join(sets)}:\n\n" + ev.format_paired(rows)


def _pareto(args: argparse.Namespace) -> str:
    from sofar_agents.evaluation.pareto_paired import format_pareto_paired

    sets = ev.read_seed_sets(args.csv)
    rows = ev.pool_seed_sets(sets)
    name = " + ".join(sets)
    return (f"Paired comparisons of the points of {name} with the fixed gammas:\n\n"
            + format_pareto_paired(rows, name, args.b or ()))


def _target_power(args: argparse.Namespace) -> str:
    from sofar_agents.evaluation.target_power import format_target_power, target_power

    sets = ev.read_seed_sets(args.csv)
    resamples = 20000
    n, rows = target_power(sets, args.target_power, args.margin, resamples)
    return f"Seed sets {', '.join(sets)}.\n\n" + format_target_power(n, rows, args.target_power, args.margin, resamples)


def _before_after(args: argparse.Namespace) -> str:
    from sofar_agents.evaluation.before_after import before_after, format_before_after

    if len(args.csv) != 2:
        raise ValueError(f"--before-after takes two CSVs (before, after), got {len(args.csv)}")
    if args.races:
        from sofar_agents.evaluation.manifest import raw_rows
        from sofar_agents.evaluation.races_before_after import format_races_before_after, races_before_after

        before, after = (raw_rows(path, kind="multi-agent") for path in args.csv)
        return (f"Before: {args.csv[0]}; after: {args.csv[1]}.\n\n"
                + format_races_before_after(races_before_after(before, after)))
    (b_name, before), (a_name, after) = ev.read_seed_sets(args.csv).items()
    return f"Before: {b_name}; after: {a_name}.\n\n" + format_before_after(before_after(before, after))


if __name__ == "__main__":
    sys.exit(main())
