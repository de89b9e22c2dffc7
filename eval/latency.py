"""The paper's Table III: MPC, MIQP and policy latency from a closed loop.

    python eval/latency.py                       # 60 s of simulated racing on Laguna Seca, 4 opponents, rho 0.3
    python eval/latency.py --seconds 20 --json results/latency.json

gamma comes from the shipped PASTA policy (or --policy); without one the loop uses a
fixed gamma of 0.5 and the RL column times an untrained 2 x 256 tanh MLP (labelled).
The logic lives in sofar_agents.evaluation.latency.
"""

from __future__ import annotations

import argparse
import logging
import sys

from sofar_agents import evaluation as ev
from sofar_agents.cli_types import gamma_value, nonneg_float, nonneg_int, positive_float


class _HelpFormatter(argparse.ArgumentDefaultsHelpFormatter):
    """Defaults in the help, except ``None`` (the help text says what happens then)."""

    def _get_help_string(self, action):
        return action.help if action.default is None else super()._get_help_string(action)


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], formatter_class=_HelpFormatter)
    p.add_argument("--seconds", type=positive_float, default=60.0,
                   help="simulated time of the closed loop [s]; the race restarts after a collision or off-track")
    p.add_argument("--json", default=None, metavar="PATH",
                   help="also write the measurements (and the machine) to this JSON file (default: none)")
    p.add_argument("--policy", default=None, metavar="PATH",
                   help="PASTA checkpoint that chooses gamma and whose inference is timed (default: the shipped "
                        "policy; without one, gamma is fixed at --gamma and an untrained MLP is timed)")
    p.add_argument("--track", default="LagunaSeca", help="circuit (LagunaSeca, Monza, Indianapolis, Kentucky)")
    p.add_argument("--rho", type=nonneg_float, default=0.3, help="opponent pace ratio (fraction of the speed profile)")
    p.add_argument("--opponents", type=nonneg_int, default=4, help="number of opponents")
    p.add_argument("--gamma", type=gamma_value, default=0.5, help="fixed gamma when there is no policy")
    p.add_argument("--seed", type=nonneg_int, default=0, help="seed of the episode start")
    p.add_argument("--log-level", default="WARNING", help="logging level (DEBUG, INFO, WARNING, ERROR)")
    return p.parse_args(argv)


def main(argv=None) -> int:
    args = parse_args(argv)
    logging.basicConfig(level=args.log_level.upper(), format="%(levelname)s %(name)s: %(message)s")
    report = ev.measure_latency(args.seconds, policy=args.policy, track=args.track, rho=args.rho,
                                n_opponents=args.opponents, fixed_gamma=args.gamma, seed=args.seed)
    print(ev.format_latency(report))
    if args.json:
        ev.write_json(args.json, report)
        print(f"Wrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
