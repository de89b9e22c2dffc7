"""Training throughput A/B: wall time of a short PASTA run with two workers, the working tree against a revision.

Usage::

    python eval/bench_train.py --compare REV [--rounds 3] [--json PATH]

The revision is exported as in ``eval/bench_env.py --compare`` (:mod:`bench_compare`). Each
round runs, in a fresh process per side and in alternating order, the side's own::

    python train/pasta.py --n-envs 2 --total-steps 4096 --n-steps 512 --seed 1 \\
        --env-kwargs '{"race": {"duration": 20.0}}' --no-progress --force --out <temporary dir>

and records its wall time (start-up, environment workers and PPO updates included). Reported:
the median and range of the wall times per side, the env steps per second they imply
(4096 / wall time) and the ratio of the medians.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from bench_compare import _git, _summary, interleave

_HERE = Path(__file__).resolve().parent
TOTAL_STEPS = 4096
TRAIN_ARGS = ["--n-envs", "2", "--total-steps", str(TOTAL_STEPS), "--n-steps", "512", "--seed", "1",
              "--env-kwargs", '{"race": {"duration": 20.0}}', "--no-progress", "--force"]


def time_training(tree: Path, out: Path) -> float:
    """Wall time [s] of the training command of :data:`TRAIN_ARGS` with the scripts and package of ``tree``."""
    env = dict(os.environ, PYTHONPATH=str(tree))
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "train/pasta.py", *TRAIN_ARGS, "--out", str(out)], cwd=str(tree),
                          env=env, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        raise RuntimeError(f"training in {tree} failed:\n{proc.stderr[-4000:]}")
    return wall


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--compare", required=True, metavar="REV", help="git revision to compare against")
    parser.add_argument("--rounds", type=int, default=3, help="rounds of one run per side, alternating (default 3)")
    parser.add_argument("--json", default=None, help="also write the results to this JSON file")
    args = parser.parse_args(argv)
    if args.rounds < 1:
        parser.error("--rounds must be >= 1")
    repo = Path(_git(_HERE, "rev-parse", "--show-toplevel"))
    old_commit, walls = interleave(repo, args.compare, args.rounds,
                                   lambda side, tree, scratch, r: time_training(tree, scratch / f"run_{side}_{r}"),
                                   lambda old, new: f"old {old:.1f} s, new {new:.1f} s")
    result = {"command": "python train/pasta.py " + " ".join(TRAIN_ARGS) + " --out DIR", "rounds": args.rounds,
              "old": {"rev": args.compare, "commit": old_commit, "wall_s": _summary(walls["old"]),
                      "env_steps_per_s": _summary([TOTAL_STEPS / w for w in walls["old"]])},
              "new": {"rev": "working tree", "commit": _git(repo, "rev-parse", "HEAD"),
                      "wall_s": _summary(walls["new"]),
                      "env_steps_per_s": _summary([TOTAL_STEPS / w for w in walls["new"]])},
              "speed_ratio_of_medians": float(np.median(walls["old"]) / np.median(walls["new"])),
              "cpu_count": os.cpu_count()}
    for side in ("old", "new"):
        w = result[side]["wall_s"]
        print(f"  {side} ({result[side]['commit'][:9]}): {w['median']:.1f} s median [{w['min']:.1f}, {w['max']:.1f}]"
              f" = {result[side]['env_steps_per_s']['median']:.0f} env steps/s")
    print(f"  speed ratio new/old: {result['speed_ratio_of_medians']:.2f}x (medians of the wall times)")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(result, fh, indent=2)
    return result


if __name__ == "__main__":
    main()
