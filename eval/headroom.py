"""How much could an adaptive gamma gain? Oracles over the fixed-gamma rows of Table I CSVs.

    python eval/headroom.py results/dynamic/table1_episodes.csv results/dynamic/seed21/table1_episodes.csv
    python eval/headroom.py results/paper_stack/table1_episodes.csv results/paper_stack/seed21/table1_episodes.csv \
        --out results/paper_stack/headroom.md

Each CSV is one seed set (run with `eval/table.py --seed ...`). For each set the script reports the
best fixed gamma, the best gamma per (circuit, rho) chosen on the set itself (an upper bound that
includes the noise), the same choice made on the other sets and scored on this one (what knowing the
conditions is honestly worth), one gamma per circuit chosen likewise, and the share of episodes that
some gamma wins; `--flips` adds, per set, the share of paired episodes whose outcome differs between
every two gammas. No episode is run: it reads the CSVs. The logic is in sofar_agents.evaluation.headroom.
"""

from __future__ import annotations

import argparse
import sys

from sofar_agents import evaluation as ev


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("csv", nargs="+", help="per-episode CSVs of Table I (table1_episodes.csv), one per seed set")
    p.add_argument("--out", default=None, help="also write the Markdown tables to this file")
    p.add_argument("--flips", action="store_true",
                   help="also the matrix of outcome flips per seed set: for every pair of gammas, the share of "
                        "paired episodes whose outcome differs (how much a race turns on small changes)")
    return p.parse_args(argv)


def main(argv=None) -> int:
    args = parse_args(argv)
    try:
        sets = ev.read_seed_sets(args.csv)
        rows = ev.headroom(sets)
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    text = ev.format_headroom(rows)
    if args.flips:
        for name, set_rows in sets.items():
            text += f"\nOutcome flips [% of paired episodes], {name}:\n\n" + ev.format_flips(ev.outcome_flips(set_rows))
    print(text, end="")
    if args.out:
        ev.write_markdown(args.out, text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
