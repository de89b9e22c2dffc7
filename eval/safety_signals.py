"""Which dense per-step signals line up with success across the fixed gammas? Seeded episodes, one row each.

    python eval/safety_signals.py --scenario interactive --env-kwargs '{"n_opponents": 8}' --seed 23000 \
        --episodes 1 --duration 120 --workers 2 --out results/interactive_dense/safety_signals

A preference-conditioned policy learns how cautious to be from its safety objective, a -1 when an episode fails.
A denser safety signal would help it only if it is smaller where the episodes succeed more often, i.e. at the
cautious gammas. For every fixed gamma this script runs the same seeded episodes (four circuits, the protocol's
rho values, ``--episodes`` per pair, ``--duration`` seconds, the default controller unless ``--stack``) and sums,
per step, the candidates the environment already measures: the MPC's largest DCBF slack (``info["barrier_slack"]``),
how deep the car is inside the nearest barrier ellipse (``max(0, -info["min_barrier"])``), the steps inside one,
and the steps closer than ``--near`` metres to an opponent's reference point (``info["nearest_opponent_m"]``).
Writes ``safety_signals.csv`` (one row per episode and gamma, with its configuration hash) and ``safety_signals.md``
(per gamma: failures and the per-step means), each atomically, with the command, the commit, the hash and the wall
time.
"""

from __future__ import annotations

import argparse
import csv
import io
import json
import logging
import math
import shlex
import subprocess
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

from sofar_agents import evaluation as ev
from sofar_agents.cli_types import float_in, nonneg_int, positive_float, positive_int
from sofar_agents.evaluation.files import write_text_atomic

logger = logging.getLogger("safety_signals")

COLUMNS = ("track", "rho", "seed", "gamma", "steps", "failed", "slack_sum", "depth_sum", "inside_steps",
           "near_steps", "config_hash")


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--scenario", default="interactive", choices=("paper", "interactive", "dynamic"))
    p.add_argument("--env-kwargs", default="{}", help="JSON of further make() arguments, e.g. '{\"n_opponents\": 8}'")
    p.add_argument("--stack", default=None, help="controller preset (default: the environment's default)")
    p.add_argument("--gammas", nargs="+", type=float_in(0.05, 1.0), default=list(ev.FIXED_GAMMAS),
                   help="the fixed gammas (default: the protocol's six)")
    p.add_argument("--seed", type=nonneg_int, default=23000, help="base seed of the episodes")
    p.add_argument("--episodes", type=positive_int, default=1, help="episodes per (circuit, rho)")
    p.add_argument("--duration", type=positive_float, default=120.0, help="episode length [s]")
    p.add_argument("--near", type=positive_float, default=8.0, help="distance counted as near [m]")
    p.add_argument("--workers", type=positive_int, default=1)
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--log-level", default="INFO")
    return p.parse_args(argv)


def run_episode(task: tuple) -> dict:
    """One seeded episode at one fixed gamma; its row of :data:`COLUMNS`."""
    import gymnasium as gym
    import numpy as np

    import sofar_env  # noqa: F401  (registers the ids)
    from sofar_env.config_hash import config_hash

    track, rho, seed, gamma, scenario, kwargs, duration, near = task
    env_id = f"SOfAR-{track}-v0" if scenario == "paper" else f"SOfAR-{track}-{scenario.capitalize()}-v0"
    env = gym.make(env_id, rho=rho, race={"duration": duration}, timing_info=False, **kwargs)
    env.reset(seed=seed)
    row = {"track": track, "rho": rho, "seed": seed, "gamma": gamma, "steps": 0, "failed": 0, "slack_sum": 0.0,
           "depth_sum": 0.0, "inside_steps": 0, "near_steps": 0, "config_hash": config_hash(env.unwrapped.config)}
    action = np.array([gamma], np.float32)
    while True:
        _, _, terminated, truncated, info = env.step(action)
        h = float(info["min_barrier"])
        row["steps"] += 1
        row["slack_sum"] += max(0.0, float(info["barrier_slack"]))
        if math.isfinite(h) and h < 0.0:
            row["depth_sum"] += -h
            row["inside_steps"] += 1
        row["near_steps"] += int(float(info["nearest_opponent_m"]) < near)
        if terminated or truncated:
            row["failed"] = int(terminated)
            env.close()
            return row


def summary(rows: list[dict], near: float) -> str:
    """Markdown table: per gamma, episodes, failures and the per-step means."""
    lines = ["| γ | episodes | failed | DCBF slack per step | depth inside an ellipse per step | steps inside an "
             f"ellipse | steps nearer than {near:g} m |", "|---:|---:|---:|---:|---:|---:|---:|"]
    for g in sorted({float(r["gamma"]) for r in rows}):
        mine = [r for r in rows if float(r["gamma"]) == g]
        steps = sum(int(r["steps"]) for r in mine)
        share = [sum(float(r[c]) for r in mine) / steps for c in ("slack_sum", "depth_sum", "inside_steps",
                                                                   "near_steps")]
        lines.append(f"| {g:g} | {len(mine)} | {sum(int(r['failed']) for r in mine)} | {share[0]:.5f} | "
                     f"{share[1]:.5f} | {100 * share[2]:.2f} % | {100 * share[3]:.2f} % |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    args = parse_args(argv)
    logging.basicConfig(level=args.log_level, format="%(levelname)s %(name)s: %(message)s")
    try:
        kwargs = json.loads(args.env_kwargs)
        if not isinstance(kwargs, dict):
            raise ValueError("it is not a JSON object")
    except ValueError as exc:
        print(f"error: --env-kwargs: {exc}", file=sys.stderr)
        return 2
    if args.stack is not None:
        kwargs["stack"] = args.stack
    tasks = [(track, rho, ev.episode_seed(args.seed, track, rho, k), g, args.scenario, kwargs, args.duration,
              args.near)
             for track in ev.TRACKS for rho in ev.RHOS for k in range(args.episodes) for g in args.gammas]
    start = time.time()
    with ProcessPoolExecutor(args.workers) as pool:
        rows = list(pool.map(run_episode, tasks))
    wall = time.time() - start
    out = Path(args.out)
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=list(COLUMNS), lineterminator="\n")
    w.writeheader()
    w.writerows(rows)
    write_text_atomic(out / "safety_signals.csv", buf.getvalue())
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip()
    command = shlex.join(["python", "eval/safety_signals.py", *(sys.argv[1:] if argv is None else argv)])
    hashes = ", ".join(sorted({r["config_hash"] for r in rows}))
    text = (f"`{command}` at {commit or '?'}, config hash {hashes}, "
            f"{len(tasks)} episodes in {wall:.0f} s.\n\n" + summary(rows, args.near))
    write_text_atomic(out / "safety_signals.md", text)
    logger.info("wrote %s", out / "safety_signals.md")
    return 0


if __name__ == "__main__":
    sys.exit(main())
