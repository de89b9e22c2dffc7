"""What the paper's Table I shows, and why: the bug-compatible controller's threshold sweep and Table I.

    python eval/reference_numerics.py sweep                 # the gamma grid, with and without phantoms
    python eval/reference_numerics.py table                 # Table I under it, beside the paper and ours
    python eval/reference_numerics.py sweep --summarize     # only re-make sweep.md / sweep.png from the CSVs
    python eval/reference_numerics.py road                  # the synthetic-road loop, beside acados' failures

``sweep`` runs fixed gammas on a fine grid with ``stack="reference-numerics"`` (the reference
implementation's numerics, defects included: ``sofar_env.control.refnum``) and a subset of it with the
control preset ``"reference-numerics-no-phantoms"`` (the same controller without the phantom opponents),
on the same seeded episodes (1 per circuit and pace ratio, i.e. 20 per gamma), then writes ``sweep.md``
(success, episodes with solver failures, failed episodes that had one, the paired effect of the phantoms)
and ``sweep.png``. ``table`` runs Table I (paper protocol: 4 circuits x 5 rho x 5 episodes per fixed
gamma) under ``"reference-numerics"`` and writes ``table1_compare.md``: its success per circuit beside the
paper's Table I and the project's ``paper`` and ``sofar`` controllers on the same seeded episodes
(``--paper-csv``, ``--sofar-csv``), with exact paired tests. Both resume from their CSVs. ``road`` runs the
closed loop of ``sofar_agents.evaluation.refnum_road`` (a synthetic road, the MPC's own model as plant) at
both ends of gamma and writes ``road.md``, next to what acados' own solver gave on the same loop.
"""

from __future__ import annotations

import argparse
import dataclasses
import logging
import sys
from pathlib import Path

from sofar_agents import evaluation as ev
from sofar_agents.cli_types import gamma_value, int_at_least, nonneg_int, positive_float
from sofar_agents.evaluation import thresholds as th
from sofar_agents.evaluation.protocol import FIXED_GAMMAS, TRACKS, Strategy

logger = logging.getLogger("reference_numerics")

STACK, CONTROL = "reference-numerics", "reference-numerics-no-phantoms"
SWEEP_GAMMAS = (0.05, 0.054, 0.058, 0.062, 0.07, 0.15, 0.30, 0.50, 0.70, 0.85, 0.87, 0.89, 0.90, 0.91, 0.93, 0.95,
                0.97)
CONTROL_GAMMAS = (0.05, 0.058, 0.50, 0.90, 0.95)
ROAD_RUNS = ((0.3, 300, (0.03, 0.05, 0.055, 0.06, 0.07, 0.1), True), (0.8, 600, (0.05, 0.5, 0.88, 0.89, 0.9, 0.95), True),
             (0.3, 300, (0.05, 0.95), False), (0.8, 600, (0.05, 0.95), False))
"""(rho, control steps, gammas, phantoms) of the synthetic-road runs."""
ACADOS_ROAD = {
    (0.3, True): "γ ≤ 0.055: 174 of 175 solves fail, off the road at 17.4 s; γ 0.06: 67 of 300; γ ≥ 0.07: none",
    (0.8, True): "γ ≤ 0.88: none (γ 0.05: 11 of 600); γ ≥ 0.90: every solve fails from the start, off the road at "
                 "17.7 s",
    (0.3, False): "no failure at any γ", (0.8, False): "no failure at any γ",
}
"""Failed solves measured on the same loop with acados (SQP_RTI, FULL_CONDENSING_HPIPM, the comma-deps-acados
0.2.2 build) and an OCP written from the same description: reference data, not re-made here."""


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter, epilog=__doc__)
    sub = p.add_subparsers(dest="command", required=True)
    s = sub.add_parser("sweep", help="success and solver failures against gamma")
    s.add_argument("--out", default="results/reference_numerics", help="results folder")
    s.add_argument("--gammas", nargs="+", type=gamma_value, default=list(SWEEP_GAMMAS))
    s.add_argument("--control-gammas", nargs="+", type=gamma_value, default=list(CONTROL_GAMMAS),
                   help="gammas also run without phantoms (the control)")
    s.add_argument("--seed", type=nonneg_int, default=31, help="base seed (default 31, a set no table uses)")
    s.add_argument("--episodes", type=int_at_least(1), default=1, help="episodes per (circuit, rho)")
    s.add_argument("--duration", type=positive_float, default=100.0, help="episode horizon [s] (default 100)")
    s.add_argument("--summarize", action="store_true", help="run nothing; re-make sweep.md and sweep.png")
    t = sub.add_parser("table", help="Table I under the bug-compatible controller, beside the paper and ours")
    t.add_argument("--out", default="results/reference_numerics", help="results folder")
    t.add_argument("--seed", type=nonneg_int, default=0, help="base seed (default 0: Table I's episodes)")
    t.add_argument("--paper-csv", default="results/paper_stack/table1_episodes.csv",
                   help="Table I episodes of stack='paper' on the same seed")
    t.add_argument("--sofar-csv", default="results/table1_episodes.csv",
                   help="Table I episodes of stack='sofar' on the same seed")
    t.add_argument("--gammas", nargs="+", type=gamma_value, default=list(FIXED_GAMMAS), help="fixed gammas")
    t.add_argument("--tracks", nargs="+", choices=TRACKS, default=list(TRACKS), help="circuits")
    t.add_argument("--policy", default=None,
                   help="a PASTA checkpoint trained under the controller: its Adaptive row is run and compared too "
                        "(results/reference_numerics/pasta/pasta_final.json)")
    t.add_argument("--folder", default="table1",
                   help="subfolder of --out for the episodes; the comparison goes to <folder>_compare.md")
    t.add_argument("--summarize", action="store_true", help="run nothing; re-make <folder>_compare.md")
    r = sub.add_parser("road", help="the synthetic-road loop at both ends of gamma, beside acados' failures")
    r.add_argument("--out", default="results/reference_numerics", help="results folder")
    for q in (s, t):
        q.add_argument("--workers", type=int_at_least(1), default=None, help="worker processes")
        q.add_argument("--no-progress", action="store_true")
    return p.parse_args(argv)


def run_sweep(args) -> str:
    out = Path(args.out) / "sweep"
    for stack, gammas in ((STACK, args.gammas), (CONTROL, args.control_gammas)):
        if not args.summarize:
            ev.run_table1(ev.build_strategies(gammas, adaptive=False), out / stack, episodes=args.episodes,
                          base_seed=args.seed, duration=args.duration, workers=args.workers,
                          progress=not args.no_progress, stack=stack)
    grid = {STACK: {Strategy.fixed(g).name for g in args.gammas},
            CONTROL: {Strategy.fixed(g).name for g in args.control_gammas}}
    rows = [r for stack in (STACK, CONTROL) if (out / stack / "table1_episodes.csv").exists()
            for r in ev.read_episode_csv(out / stack / "table1_episodes.csv") if r["strategy"] in grid[stack]]
    points = th.sweep_points(rows)
    effects = th.phantom_effects(rows, STACK, CONTROL)
    (low, high) = th.failure_edges(rows, STACK)
    excess = th.failure_excess(rows, STACK)
    text = ["# Threshold sweep of the bug-compatible controller\n",
            f"Fixed gammas under `stack=\"{STACK}\"` and, on the same seeded episodes, `\"{CONTROL}\"`; "
            f"base seed {args.seed}, {args.duration:g} s per episode, 1 episode per circuit and pace ratio "
            f"(4 circuits x 5 rho). Predicted edges of the failure zones: γ < {th.PREDICTED_THRESHOLDS[0]} "
            f"and γ > {th.PREDICTED_THRESHOLDS[1]}.\n",
            th.format_sweep(points, effects, STACK, CONTROL),
            "\n## Episodes with failed solves against γ = 0.5, paired\n",
            "| γ | episodes | with a failed solve | the same episodes at γ = 0.5 | p (exact McNemar) |",
            "|---:|---:|---:|---:|---:|",
            *(f"| {g:g} | {n} | {k} | {k_ref} | {p:.3g} |" for g, (n, k, k_ref, p) in excess.items()),
            f"\nEdges of the failure zones (the first γ, walking away from 0.5, with more episodes with failed "
            f"solves than at 0.5, paired p < 0.05): low side between γ = {low[0]} and {low[1]}, high side "
            f"between γ = {high[0]} and {high[1]} (None: no such γ on that side).\n"]
    ev.write_markdown(Path(args.out) / "sweep.md", "\n".join(text))
    th.plot_sweep(points, Path(args.out) / "sweep.png", STACK, CONTROL)
    return "\n".join(text)


def run_table(args) -> str:
    out = Path(args.out) / args.folder
    gammas = tuple(args.gammas)
    if not args.summarize:
        strategies = ev.build_strategies(gammas, policy=args.policy, adaptive=args.policy is not None)
        ev.run_table1(strategies, out, tracks=args.tracks, base_seed=args.seed,
                      workers=args.workers, progress=not args.no_progress, stack=STACK)
    sets = {"refnum": ev.read_episode_csv(out / "table1_episodes.csv")}
    for name, path in (("paper", args.paper_csv), ("sofar", args.sofar_csv)):
        if Path(path).exists():
            sets[name] = ev.read_episode_csv(path)
    rows = [r for rs in sets.values() for r in rs]
    per = ev.aggregate(ev.label_by_stack({"all": rows})["all"], ("track", "strategy"))
    stacks = [s for s in (STACK, "paper", "sofar-1", "sofar") if any((r.get("stack") or "sofar-1") == s for r in rows)]
    lines = ["# Table I under the bug-compatible controller, beside the paper's and the project's controllers\n",
             f"Success [%] per circuit and fixed γ; the project's rows on the same seeded episodes (base seed "
             f"{args.seed}, 25 per circuit and γ; `all`: the circuits of this run).\n",
             "| Track | γ | paper's Table I | " + " | ".join(f"`{s}`" for s in stacks) + " |",
             "|---|---:|---:|" + "---:|" * len(stacks)]
    for track in [*args.tracks, "all"]:
        for g in gammas:
            strategy = Strategy.fixed(g).name
            cells = []
            for s in stacks:
                if track == "all":
                    hits = [r for r in rows if (r.get("stack") or "sofar-1") == s and r["strategy"] == strategy
                            and r["track"] in args.tracks]
                    cells.append(f"{100 * sum(bool(r['success']) for r in hits) / len(hits):.0f}" if hits else "–")
                else:
                    summ = per.get((track, f"{s}:{strategy}"))
                    cells.append(f"{summ.success_rate:.0f}" if summ else "–")
            paper = (sum(ev.PAPER_TABLE1_SUCCESS[t][g] for t in args.tracks) / len(args.tracks) if track == "all"
                     else ev.PAPER_TABLE1_SUCCESS[track][g])
            lines.append(f"| {track} | {g:g} | {paper:.0f} | " + " | ".join(cells) + " |")
    pooled = ev.label_by_stack({"all": rows})
    comparisons = []
    for g in gammas:
        strategy = Strategy.fixed(g).name
        for other in stacks[1:]:
            try:
                comparisons.append(ev.paired_comparison(pooled, f"{STACK}:{strategy}", f"{other}:{strategy}"))
            except ValueError:
                continue
    mids = [f"{STACK}:{Strategy.fixed(g).name}" for g in gammas if 0.1 < g < 0.9]
    for g in (0.05, 0.95):
        for mid in mids:
            try:
                comparisons.append(ev.paired_comparison(pooled, f"{STACK}:{Strategy.fixed(g).name}", mid))
            except ValueError:
                continue
    groups = {"road courses": ("LagunaSeca", "Monza"), "ovals": ("Indianapolis", "Kentucky")}
    by_group = []
    for group, tracks in groups.items():
        sub = {"all": [r for r in pooled["all"] if r["track"] in tracks]}
        for g in (0.05, 0.95):
            for mid in mids:
                try:
                    c = ev.paired_comparison(sub, f"{STACK}:{Strategy.fixed(g).name}", mid)
                except ValueError:
                    continue
                by_group.append(dataclasses.replace(c, a=f"{c.a}, {group}"))
    refnum = [r for r in rows if (r.get("stack") or "sofar-1") == STACK]
    points = th.sweep_points(refnum)
    adaptive = [r for r in refnum if r["strategy"] == "adaptive"]
    if adaptive:
        n = len(adaptive)
        mean_gamma = sum(float(r["mean_gamma"]) for r in adaptive) / n
        ad = [ev.paired_comparison(pooled, f"{STACK}:adaptive", f"{STACK}:{Strategy.fixed(g).name}") for g in gammas]
        lines += ["\n## The adaptive policy trained under the bug-compatible controller\n",
                  f"{n} episodes, success {100 * sum(bool(r['success']) for r in adaptive) / n:.0f} %, mean γ "
                  f"{mean_gamma:.3f}, against each fixed γ on the same episodes:\n", ev.format_paired(ad)]
    lines += ["\n## Solver failures under the bug-compatible controller\n",
              "| γ | episodes | success [%] | episodes with a failed solve | failed episodes with a failed solve |",
              "|---:|---:|---:|---:|---:|",
              *(f"| {p.gamma:g} | {p.episodes} | {100 * p.success_rate:.0f} | {p.solver_failure_episodes} "
                f"| {p.failed_with_solver_failure} of {p.failed} |" for p in points),
              "\n## Paired tests (exact McNemar, episodes matched by circuit, rho and seed)\n",
              ev.format_paired(comparisons),
              "\n### The extremes against the middle gammas: road courses (Laguna Seca, Monza) and ovals "
              "(Indianapolis, Kentucky)\n",
              ev.format_paired(by_group)]
    text = "\n".join(lines)
    ev.write_markdown(Path(args.out) / f"{args.folder}_compare.md", text)
    return text


def run_road(args) -> str:
    from sofar_agents.evaluation.refnum_road import road_loop

    lines = ["# The bug-compatible MPC on the synthetic road, beside acados\n",
             "Failed solves (HPIPM status) per run; the car leaves the road when |n| > 20 m.\n",
             "| rho | phantoms | γ | steps | failed solves | HPIPM statuses (0/1/2/3) | left the road at [s] |",
             "|---:|---|---:|---:|---:|---|---:|"]
    for rho, steps, gammas, phantoms in ROAD_RUNS:
        for g in gammas:
            out = road_loop(g, rho, steps, phantoms)
            st = "/".join(str(out.qp_status.get(k, 0)) for k in range(4))
            lines.append(f"| {rho:g} | {'yes' if phantoms else 'no'} | {g:g} | {out.steps} | {out.failures} | {st} "
                         f"| {out.left_road_at if out.left_road_at is not None else '–'} |")
    lines += ["\nThe same loop with acados' own SQP_RTI and FULL_CONDENSING_HPIPM:\n",
              *(f"- rho {rho:g}, {'with' if ph else 'without'} phantoms: {text}"
                for (rho, ph), text in ACADOS_ROAD.items())]
    text = "\n".join(lines) + "\n"
    ev.write_markdown(Path(args.out) / "road.md", text)
    return text


def main(argv=None) -> int:
    args = parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    text = {"sweep": run_sweep, "table": run_table, "road": run_road}[args.command](args)
    sys.stdout.write(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
