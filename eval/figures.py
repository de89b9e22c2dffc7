"""The paper's Fig. 5: histogram of gamma and nearest-opponent distance vs gamma.

    python eval/figures.py                                  # 3 adaptive episodes on Laguna Seca, then plot
    python eval/figures.py --episodes 5 --rhos 0.3 0.5 --policy runs/pasta/pasta_final.json
    python eval/figures.py --trace results/table1_trace.csv # plot a trace written by `eval/table.py --trace`
    python eval/figures.py --scenario interactive --opponents 8 --out results/interactive_dense/figures

PNG files go to results/figures/ (--out). Recorded episodes are kept in
<out>/episodes.csv and <out>/trace.csv and reused on a rerun with the same policy (a folder
that holds another policy's episodes is refused: the trace rows carry no policy id). The logic lives in
sofar_agents.evaluation (sweep.py records the episodes, figures.py draws).
"""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

import numpy as np

from sofar_agents import evaluation as ev
from sofar_agents.evaluation.figures import FIGURE_TRACE, gamma_summary, record_figure_episodes
from sofar_agents.cli_types import nonneg_float, nonneg_int, positive_float, positive_int
from sofar_env.scenarios import SCENARIOS
from sofar_env.stack.config import STACK_PRESETS


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    p.add_argument("--trace", default=None, help="plot this per-step trace CSV instead of running episodes")
    p.add_argument("--strategy", default="adaptive", help="strategy of the trace to plot")
    p.add_argument("--out", default="results/figures", help="output folder")
    p.add_argument("--policy", default=None, help="policy checkpoint (default: the shipped one)")
    p.add_argument("--track", default="LagunaSeca")
    p.add_argument("--stack", default="sofar", choices=STACK_PRESETS,
                   help=f"controller preset, one of {', '.join(STACK_PRESETS)} (default sofar; also picks the "
                        "shipped policy)")
    p.add_argument("--scenario", default="paper", choices=SCENARIOS,
                   help=f"world, one of {', '.join(SCENARIOS)} (default paper; the shipped policy of --stack and "
                        "--scenario is the default)")
    p.add_argument("--opponents", type=nonneg_int, default=None,
                   help="opponents per episode (default: the environment's 4)")
    p.add_argument("--episodes", type=positive_int, default=3, help="episodes per rho")
    p.add_argument("--rhos", nargs="+", type=nonneg_float, default=[0.3])
    p.add_argument("--duration", type=positive_float, default=ev.DEFAULT_DURATION, help="episode horizon [s]")
    p.add_argument("--seed", type=nonneg_int, default=0)
    p.add_argument("--workers", type=positive_int, default=None)
    p.add_argument("--backend", default="local", choices=("local", "ray"),
                   help="local: a process pool on this machine; ray: Ray actors (pip install \"sofar[ray]\")")
    p.add_argument("--address", default=None,
                   help="with --backend ray: 'auto' or HOST:6379 joins a running Ray cluster (the package must be "
                        "installed on every node); default: start a local Ray instance with --workers CPUs")
    p.add_argument("--max-distance", type=positive_float, default=100.0, help="x range of the distance plot [m]")
    p.add_argument("--log-level", default="WARNING")
    return p.parse_args(argv)


def main(argv=None) -> int:
    args = parse_args(argv)
    logging.basicConfig(level=args.log_level.upper(), format="%(levelname)s %(name)s: %(message)s")
    out = Path(args.out)
    if args.trace:
        trace_path = Path(args.trace)
    else:
        policy = ev.resolve_policy_path(args.policy, stack=args.stack, scenario=args.scenario)
        if policy is None:
            print("error: no adaptive policy to record (train one or pass --policy PATH)", file=sys.stderr)
            return 2
        strategies = [ev.Strategy.adaptive(policy)]
        trace_path = out / FIGURE_TRACE
        try:
            stats = record_figure_episodes(strategies, out, tracks=[args.track], rhos=args.rhos,
                                           episodes=args.episodes, seed=args.seed, duration=args.duration,
                                           stack=args.stack, scenario=args.scenario, n_opponents=args.opponents,
                                           workers=args.workers, backend=args.backend, address=args.address)
        except (ImportError, ValueError) as exc:  # --backend ray without Ray; a folder of another policy
            print(f"error: {exc}", file=sys.stderr)
            return 2
        incomplete = ev.incomplete_message(stats, out)
        if incomplete:  # the figures are drawn from the finished episodes
            logging.getLogger("figures").warning(incomplete)
    trace = ev.read_trace_csv(trace_path, strategy=args.strategy)
    if trace["gamma"].size == 0:
        print(f"error: no steps of strategy {args.strategy!r} in {trace_path}", file=sys.stderr)
        return 2
    paths = ev.plot_gamma_figures(trace, out, max_distance=args.max_distance)
    print(gamma_summary(trace))
    for p in paths:
        print(f"Wrote {p}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
