"""A Pareto view: success against overtakes per hour for every fixed gamma and a preference-conditioned policy.

    python eval/pareto.py                                  # Table I protocol, shipped policy at 5 preferences
    python eval/pareto.py --scenario interactive --policy runs/pasta_int/pasta_final --workers 2
    python eval/pareto.py --quick                          # a quick look (~1 min): 1 circuit, 1 episode of 30 s
    python eval/pareto.py --pool A/pareto_episodes.csv B/pareto_episodes.csv --out DIR   # seed sets pooled
    python eval/pareto.py --bootstrap A/pareto_episodes.csv [B/...] --out DIR       # hypervolume vs. episode noise
    python eval/pareto.py --training-seeds S1/pareto_episodes.csv S2/... --out DIR   # a recipe over its seeds

Each strategy is evaluated on the same seeded episodes and reported as (aggregate success %,
overtakes per hour of racing); the hypervolume of each family's front (fixed gammas; the policy's
preference sweep) comes from pymoo's HV indicator. Writes <out>/pareto.md, pareto.json, pareto.png and the
per-episode CSV (rerunning the same command resumes it). ``--pool`` runs nothing: it pools the episodes of
several seed sets of one front (the strategies every file holds) into <out>/pareto_pooled.md, with each
strategy's mean gamma. ``--bootstrap`` runs nothing either: it draws the episodes of one or several seed sets
again (paired, within each circuit and rho) and writes to <out>/hv_bootstrap.md how the difference of the policy's
and the fixed gammas' hypervolumes spreads. ``--training-seeds`` runs nothing: given the files of policies trained
by one recipe with different seeds on the same episodes, it writes <out>/training_seeds.md: each seed's front, the
recipe's difference (the mean of the seeds') with bootstraps over the episodes and over the seeds, and the pooled
front. The logic is in sofar_agents.evaluation.pareto, .pareto_bootstrap and .pareto_seeds.
"""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

from sofar_agents import evaluation as ev
from sofar_agents.cli_types import gamma_value, nonneg_float, nonneg_int, positive_float, positive_int
from sofar_env.scenarios import SCENARIOS
from sofar_env.stack.config import STACK_PRESETS

QUICK_DURATION = 30.0
"""Episode horizon of --quick [s]."""
DEFAULT_SAFETY_WEIGHTS = (0.1, 0.3, 0.5, 0.7, 0.9)
"""Safety weights of the default preference sweep (overtakes get 0.9 minus it, the other three 0.1 / 3 each)."""


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", default=None,
                   help="output folder (default results/pareto, results/<scenario>/pareto for another world, "
                        "or results/quick with --quick)")
    p.add_argument("--policy", default=None,
                   help="PASTA checkpoint (default: the one shipped for --stack / --scenario, if any)")
    p.add_argument("--no-policy", action="store_true", help="only the fixed gammas")
    p.add_argument("--sb3", default=None, help="an SB3 PPO zip (train/ppo.py) evaluated as one more point")
    p.add_argument("--safety-weights", nargs="+", type=nonneg_float, default=None,
                   help="safety weights of the policy's preferences, each in [0, 0.9] "
                        f"(default {' '.join(f'{w:g}' for w in DEFAULT_SAFETY_WEIGHTS)}); the overtakes weight is "
                        "0.9 minus it and progress, barrier margin and gamma smoothness get 0.1 / 3 each")
    p.add_argument("--gammas", nargs="+", type=gamma_value, default=None,
                   help=f"fixed gammas (default {' '.join(f'{g:.2f}' for g in ev.FIXED_GAMMAS)})")
    p.add_argument("--tracks", nargs="+", default=None, help=f"circuits (default {' '.join(ev.TRACKS)})")
    p.add_argument("--rhos", nargs="+", type=nonneg_float, default=None,
                   help=f"opponent pace ratios (default {' '.join(f'{r:g}' for r in ev.RHOS)})")
    p.add_argument("--episodes", type=positive_int, default=None, help="episodes per (track, rho) (default 5)")
    p.add_argument("--duration", type=positive_float, default=None,
                   help=f"episode horizon [s] (default {ev.DEFAULT_DURATION:g})")
    p.add_argument("--scenario", default="paper", choices=SCENARIOS,
                   help=f"world, one of {', '.join(SCENARIOS)} (default paper)")
    p.add_argument("--stack", default="sofar", choices=STACK_PRESETS,
                   help=f"controller preset, one of {', '.join(STACK_PRESETS)} (default sofar)")
    p.add_argument("--opponents", type=nonneg_int, default=None,
                   help="opponents per episode (default: the environment's 4; part of the resume key)")
    p.add_argument("--seed", type=nonneg_int, default=0, help="base seed of the paired episode seeds")
    p.add_argument("--workers", type=positive_int, default=None, help="worker processes (default: os.cpu_count())")
    p.add_argument("--backend", default="local", choices=("local", "ray"), help="local process pool or Ray actors")
    p.add_argument("--address", default=None, help="with --backend ray: 'auto' or HOST:6379")
    p.add_argument("--quick", action="store_true",
                   help=f"a quick look: Laguna Seca, rho 0.5, 1 episode of {QUICK_DURATION:g} s, gammas 0.3 and "
                        "0.7, safety weights 0.2 and 0.8, to results/quick; explicit options override")
    p.add_argument("--pool", nargs="+", default=None, metavar="CSV",
                   help="run nothing: pool these pareto_episodes.csv files (seed sets of one front) into "
                        "<out>/pareto_pooled.md (--out required)")
    p.add_argument("--bootstrap", nargs="+", default=None, metavar="CSV",
                   help="run nothing: the paired bootstrap of the hypervolume of the policy's front minus the fixed "
                        "gammas' over the episodes of these pareto_episodes.csv files (pooled) into "
                        "<out>/hv_bootstrap.md (--out required)")
    p.add_argument("--training-seeds", nargs="+", default=None, metavar="CSV",
                   help="run nothing: the front of one training recipe over these pareto_episodes.csv files, one "
                        "per training seed on the same episodes and fixed-gamma rows, into <out>/training_seeds.md "
                        "(--out required)")
    p.add_argument("--resamples", type=positive_int, default=2000,
                   help="with --bootstrap or --training-seeds: draws (default 2000, at least 100)")
    p.add_argument("--bootstrap-seed", type=nonneg_int, default=0,
                   help="with --bootstrap or --training-seeds: seed of the draws (default 0)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--log-level", default="WARNING")
    return p.parse_args(argv)


def main(argv=None) -> int:
    args = parse_args(argv)
    logging.basicConfig(level=args.log_level.upper(), format="%(levelname)s %(name)s: %(message)s")
    if sum(bool(x) for x in (args.pool, args.bootstrap, args.training_seeds)) > 1:
        print("error: give one of --pool, --bootstrap and --training-seeds", file=sys.stderr)
        return 2
    if args.training_seeds:
        return _training_seeds(args.training_seeds, args.out, args.resamples, args.bootstrap_seed)
    if args.pool:
        return _pool(args.pool, args.out)
    if args.bootstrap:
        return _bootstrap(args.bootstrap, args.out, args.resamples, args.bootstrap_seed)
    policy = None if args.no_policy else ev.resolve_policy_path(
        args.policy, fallback="only the fixed gammas are evaluated", stack=args.stack, scenario=args.scenario)
    try:
        preferences = ev.preference_family(args.safety_weights or ((0.2, 0.8) if args.quick else DEFAULT_SAFETY_WEIGHTS))
    except ValueError as exc:
        print(f"error: --safety-weights: {exc}", file=sys.stderr)
        return 2
    gammas = args.gammas or ([0.3, 0.7] if args.quick else list(ev.FIXED_GAMMAS))
    tracks = args.tracks or (["LagunaSeca"] if args.quick else list(ev.TRACKS))
    rhos = args.rhos or ([0.5] if args.quick else list(ev.RHOS))
    episodes = args.episodes or (1 if args.quick else 5)
    duration = args.duration or (QUICK_DURATION if args.quick else ev.DEFAULT_DURATION)
    default_out = "results/pareto" if args.scenario == "paper" else f"results/{args.scenario}/pareto"
    out = args.out or ("results/quick" if args.quick else default_out)
    try:
        report = ev.run_pareto(policy, preferences, gammas, out, tracks=tracks, rhos=rhos, episodes=episodes,
                               base_seed=args.seed, duration=duration, workers=args.workers,
                               progress=not args.no_progress, stack=args.stack, scenario=args.scenario,
                               backend=args.backend, address=args.address, n_opponents=args.opponents,
                               sb3=args.sb3)
    except KeyboardInterrupt:
        print(f"\ninterrupted: finished episodes are in {out}; rerun the same command to resume", file=sys.stderr)
        return 130
    except (ImportError, ValueError) as exc:  # --backend ray without Ray; a preference the policy cannot take
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(report.markdown)
    print("Wrote " + ", ".join(str(p) for p in report.paths.values()))
    incomplete = ev.incomplete_message(report.stats, out)
    if incomplete:
        logging.getLogger("pareto").error(incomplete)
        return 1
    return 0


def _pool(csvs: list[str], out: str | None) -> int:
    if out is None:
        print("error: --pool needs --out", file=sys.stderr)
        return 2
    try:
        *_, md = ev.pooled_pareto(csvs)
    except ValueError as exc:
        print(f"error: --pool: {exc}", file=sys.stderr)
        return 2
    path = ev.write_markdown(Path(out) / "pareto_pooled.md", md)
    print(md)
    print(f"Wrote {path}")
    return 0


def _bootstrap(csvs: list[str], out: str | None, resamples: int, seed: int) -> int:
    if out is None:
        print("error: --bootstrap needs --out", file=sys.stderr)
        return 2
    try:
        rows = ev.pool_seed_sets(ev.read_seed_sets(csvs))
        result = ev.bootstrap_hypervolume(rows, resamples=resamples, seed=seed)
    except ValueError as exc:
        print(f"error: --bootstrap: {exc}", file=sys.stderr)
        return 2
    md = ev.bootstrap_markdown(result, csvs)
    path = ev.write_markdown(Path(out) / "hv_bootstrap.md", md)
    print(md)
    print(f"Wrote {path}")
    return 0


def _training_seeds(csvs: list[str], out: str | None, resamples: int, seed: int) -> int:
    if out is None:
        print("error: --training-seeds needs --out", file=sys.stderr)
        return 2
    try:
        result = ev.training_seed_fronts(ev.read_seed_sets(csvs), resamples=resamples, seed=seed)
    except ValueError as exc:
        print(f"error: --training-seeds: {exc}", file=sys.stderr)
        return 2
    md = ev.training_seeds_markdown(result)
    path = ev.write_markdown(Path(out) / "training_seeds.md", md)
    print(md)
    print(f"Wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
