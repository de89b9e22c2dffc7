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


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    p.add_argument("--seconds", type=float, default=60.0, help="simulated time of the closed loop [s]")
    p.add_argument("--json", default=None, help="write the measurements to this JSON file")
    p.add_argument("--policy", default=None, help="policy checkpoint (default: the shipped one)")
    p.add_argument("--track", default="LagunaSeca")
    p.add_argument("--rho", type=float, default=0.3)
    p.add_argument("--opponents", type=int, default=4)
    p.add_argument("--gamma", type=float, default=0.5, help="fixed gamma when there is no policy")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--log-level", default="WARNING")
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
