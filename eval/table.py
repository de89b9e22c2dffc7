"""The paper's Table I (per-circuit comparison) and, with --miqp-ablation, Table II.

    python eval/table.py                         # full Table I: 4 circuits x 5 rho x 5 episodes x 7 strategies
    python eval/table.py --quick                 # a quick look: 2 circuits, rho 0.5, 1 episode of 30 s
    python eval/table.py --miqp-ablation         # Table II: Laguna Seca with / without the MIQP layer
    python eval/table.py --sb3 runs/ppo/model.zip --workers 2 --out results/
    python eval/table.py --backend ray [--address auto]   # episodes on Ray (local instance or a cluster)
    python eval/table.py --multi-agent           # PettingZoo races: 4 cars, 200 s, 4 circuits x 4 seeded races
    python eval/table.py --multi-agent --self-play runs/selfplay/pasta_final.json --gammas 0.3 0.5 --workers 1

Results (per-episode CSV, Markdown table) go to --out; rerunning the same command
skips the episodes already in the CSV. A run that leaves episodes (races) out (failed, or lost
with a worker process that died) says how many and exits with status 1; numbers out of
range are usage errors (status 2). The worker processes end with this one, even when it
is killed. The logic lives in sofar_agents.evaluation (experiments.py runs a table;
protocol.py says which episodes it holds).
"""

from __future__ import annotations

import argparse
import logging
import sys

from sofar_agents import evaluation as ev
from sofar_agents.cli_types import gamma_value, int_at_least, nonneg_float, nonneg_int, positive_float, positive_int
from sofar_env.scenarios import SCENARIOS
from sofar_env.stack.config import STACK_PRESETS

logger = logging.getLogger("table")

QUICK_DURATION = 30.0
"""Episode horizon of --quick [s]: long enough for a few overtakes (3-4 per episode at rho 0.5)."""


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", default=None, help="output folder (default results/, or results/quick with --quick)")
    p.add_argument("--workers", type=positive_int, default=None, help="worker processes (default: os.cpu_count())")
    p.add_argument("--backend", default="local", choices=("local", "ray"),
                   help="local: a process pool on this machine; ray: Ray actors (pip install \"sofar[ray]\"). Ray's "
                        "start-up (the instance, then every worker's imports and environments) can dominate a small "
                        "sweep such as --quick (both timed in results/first_ten_minutes.md); it pays off on long "
                        "sweeps and on a cluster")
    p.add_argument("--address", default=None,
                   help="with --backend ray: 'auto' or HOST:6379 joins a running Ray cluster (the package must be "
                        "installed on every node); default: start a local Ray instance with --workers CPUs")
    p.add_argument("--quick", action="store_true",
                   help=f"a quick look: LagunaSeca + Monza, rho 0.5, 1 episode of {QUICK_DURATION:g} s (300 control "
                        "steps) per strategy, Adaptive + gamma 0.5 (gamma 0.3 + 0.5 without a policy), written to "
                        "results/quick; explicit options override")
    p.add_argument("--miqp-ablation", action="store_true", help="Table II instead of Table I")
    p.add_argument("--multi-agent", action="store_true",
                   help="the multi-agent table: races of the PettingZoo environment (--cars cars, every car driven "
                        "by the same strategy; --episodes races per circuit, seeded from --seed and the circuit), "
                        "written to results/multi_agent")
    p.add_argument("--cars", type=int_at_least(2), default=4,
                   help="with --multi-agent: controlled cars per race (default 4)")
    p.add_argument("--self-play", default=None,
                   help="with --multi-agent: also evaluate this PASTA checkpoint (e.g. from train/pasta.py "
                        "--multi-agent), as the strategy 'self-play'")
    p.add_argument("--tracks", nargs="+", default=None, help=f"circuits (default {' '.join(ev.TRACKS)})")
    p.add_argument("--rhos", nargs="+", type=nonneg_float, default=None,
                   help=f"opponent pace ratios (default {' '.join(f'{r:g}' for r in ev.RHOS)})")
    p.add_argument("--episodes", type=positive_int, default=None,
                   help="episodes per (track, rho) for Table I (default 5); per (setting, strategy) for Table II "
                        "(default 10, rho cycling)")
    p.add_argument("--gammas", nargs="+", type=gamma_value, default=None,
                   help=f"fixed gammas (default {' '.join(f'{g:.2f}' for g in ev.FIXED_GAMMAS)}; Table II: 0.5)")
    p.add_argument("--duration", type=positive_float, default=None,
                   help=f"episode horizon [s] (default {ev.DEFAULT_DURATION:g})")
    p.add_argument("--scenario", default="paper", choices=SCENARIOS,
                   help=f"world, one of {', '.join(SCENARIOS)} (default paper; sofar_env.scenarios)")
    p.add_argument("--stack", default="sofar", choices=STACK_PRESETS,
                   help=f"controller preset, one of {', '.join(STACK_PRESETS)} (default sofar; paper is the paper's "
                        "Algorithm 1 as written; sofar_env.stack.stack_preset)")
    p.add_argument("--opponents", type=nonneg_int, default=None,
                   help="Table I: opponents per episode (default: the environment's 4); with --multi-agent: scripted "
                        "opponents besides the controlled cars (default 0); part of the resume key")
    p.add_argument("--seed", type=nonneg_int, default=0, help="base seed of the paired episode seeds")
    p.add_argument("--policy", default=None, help="adaptive policy checkpoint (default: the shipped one)")
    p.add_argument("--no-adaptive", action="store_true", help="leave out the adaptive policy")
    p.add_argument("--sb3", default=None, help="also evaluate a Stable-Baselines3 PPO policy (.zip)")
    p.add_argument("--trace", action="store_true",
                   help="write a per-step trace (gamma, nearest opponent, min barrier) of the non-fixed strategies")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--log-level", default="WARNING")
    return p.parse_args(argv)


def main(argv=None) -> int:
    args = parse_args(argv)
    logging.basicConfig(level=args.log_level.upper(), format="%(levelname)s %(name)s: %(message)s")
    if args.multi_agent:
        return multi_agent_main(args)
    policy = None if args.no_adaptive else ev.resolve_policy_path(args.policy, stack=args.stack, scenario=args.scenario)
    if args.miqp_ablation:
        gammas = args.gammas or [0.5]
        episodes = args.episodes or (1 if args.quick else 10)
        rhos = args.rhos or ([0.5] if args.quick else list(ev.RHOS))
    else:
        gammas = args.gammas or (([0.5] if policy else [0.3, 0.5]) if args.quick else list(ev.FIXED_GAMMAS))
        episodes = args.episodes or (1 if args.quick else 5)
        rhos = args.rhos or ([0.5] if args.quick else list(ev.RHOS))
    tracks = args.tracks or (["LagunaSeca", "Monza"] if args.quick else list(ev.TRACKS))
    duration = args.duration or (QUICK_DURATION if args.quick else ev.DEFAULT_DURATION)
    out = args.out or ("results/quick" if args.quick else "results")
    strategies = ev.build_strategies(gammas, policy=policy, sb3=args.sb3, adaptive=policy is not None)
    common = dict(stack=args.stack, scenario=args.scenario, base_seed=args.seed, duration=duration, workers=args.workers,
                  progress=not args.no_progress, backend=args.backend, address=args.address)
    try:
        if args.miqp_ablation:
            report = ev.run_miqp_ablation(strategies, out, episodes=episodes, rhos=rhos, **common)
        else:
            report = ev.run_table1(strategies, out, tracks=tracks, rhos=rhos, episodes=episodes, trace=args.trace,
                                   n_opponents=args.opponents, **common)
    except KeyboardInterrupt:
        print(f"\ninterrupted: finished episodes are in {out}; rerun the same command to resume", file=sys.stderr)
        return 130
    except ImportError as exc:  # --backend ray without Ray
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(report.markdown)
    st = report.stats
    if st.completed:
        rate = st.steps_per_second_per_worker
        full_h = st.estimate_hours(ev.FULL_TABLE1_STEPS, st.workers)
        print(f"Speed: {rate:.0f} control steps/s per worker; a full Table I "
              f"({ev.FULL_TABLE1_STEPS / 1e6:.1f} M steps) would take about {full_h:.1f} h on {st.workers} "
              f"worker{'' if st.workers == 1 else 's'}.")
    print(f"Wrote {report.csv_path} and {report.markdown_path}")
    incomplete = ev.incomplete_message(st, out)
    if incomplete:
        logger.error(incomplete)
        return 1
    return 0


def multi_agent_main(args: argparse.Namespace) -> int:
    """``--multi-agent``: the races of :mod:`sofar_agents.evaluation.multi_agent`."""
    from sofar_agents.evaluation.multi_agent import run_multi_agent_table

    if args.miqp_ablation or args.backend != "local" or args.sb3 or args.trace or args.rhos:
        print("error: --multi-agent takes none of --miqp-ablation, --backend ray, --sb3, --trace, --rhos",
              file=sys.stderr)
        return 2
    policy = None if args.no_adaptive else ev.resolve_policy_path(args.policy, stack=args.stack, scenario=args.scenario)
    strategies = ev.build_strategies(args.gammas or list(ev.FIXED_GAMMAS), policy=policy,
                                     adaptive=policy is not None)
    if args.self_play:
        strategies.append(ev.Strategy.adaptive(args.self_play, name="self-play"))
    episodes = args.episodes or (1 if args.quick else 4)
    tracks = args.tracks or (["LagunaSeca"] if args.quick else list(ev.TRACKS))
    duration = args.duration or (QUICK_DURATION if args.quick else ev.DEFAULT_DURATION)
    out = args.out or ("results/quick" if args.quick else "results/multi_agent")
    try:
        report = run_multi_agent_table(strategies, out, tracks=tracks, races=episodes, base_seed=args.seed,
                                       cars=args.cars, duration=duration, stack=args.stack, scenario=args.scenario,
                                       workers=args.workers, progress=not args.no_progress,
                                       opponents=args.opponents or 0)
    except KeyboardInterrupt:
        print(f"\ninterrupted: finished races are in {out}; rerun the same command to resume", file=sys.stderr)
        return 130
    print(report.markdown)
    print(f"Wrote {report.csv_path} and {report.markdown_path}")
    incomplete = ev.incomplete_message(report.stats, out, unit="races")
    if incomplete:
        logger.error(incomplete)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
