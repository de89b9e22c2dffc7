"""Training throughput: a short PASTA run with two workers, the working tree against a revision or backend against backend.

Usage::

    python bench/bench_train.py --compare REV [--backend B [--scenario S]] [--rounds 3] [--json PATH]
    python bench/bench_train.py --backends one-process local processes [ray] [--scenario S] [--multi-agent CARS]
                               [--rounds 3] [--json PATH]

The revision is exported as in ``bench/bench_env.py --compare`` (:mod:`bench_compare`). Each
round runs, in a fresh process per side and in alternating order, the side's own::

    python train/pasta.py --n-envs 2 --total-steps 4096 --n-steps 512 --seed 1 \\
        --env-kwargs '{"race": {"duration": 20.0}}' --no-progress --force --out <temporary dir>

and records its wall time (start-up, environment workers and PPO updates included); before its first timed
run, each side makes one short untimed run (:data:`WARM_UP_ARGS`), so that the exported revision's numba
kernels are compiled and cached outside the timing, as the working tree's already are. Reported:
the median and range of the wall times per side, the env steps per second they imply
(4096 / wall time) and the ratio of the medians. With ``--backend B`` (and optionally ``--scenario S``)
each side runs instead the longer command of the set-up ``B`` of ``--backends`` below, and the collection
throughput of each side (see below) is reported with its per-round ratio.

With ``--backends`` the working tree's training runs with each named set-up in turn (the order rotates
every round), on episodes of the default length (200 s) and longer rollouts::

    python train/pasta.py --total-steps 8192 --seed 1 --no-progress --force --n-envs 2 --n-steps 1024 \\
        --backend B --out <temporary dir>

with ``B`` one of ``local``, ``processes`` and ``ray``; the set-up ``one-process`` is ``--n-envs 1 --n-steps
2048 --backend local`` (the env stepped in the learner's process: the reference for "N workers against one
process").

Besides the wall time (which includes each backend's start-up: Ray's is several seconds), the
collection throughput is read from the run's TensorBoard log: env steps collected over the time
spent collecting (``time/collect_s``, policy evaluation included, PPO updates and start-up left
out). Reported per set-up: medians and ranges, and each set-up's per-round ratio to the first.
The three backends give the same checkpoints, so only their times differ (``one-process`` trains on
one env, so its run differs).
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from bench_compare import _git, _summary, interleave

from sofar_agents.cli_types import int_at_least, positive_int
from sofar_agents.evaluation.files import write_json_atomic
from sofar_env.scenarios import SCENARIOS

_HERE = Path(__file__).resolve().parent
TOTAL_STEPS = 4096
TRAIN_ARGS = ["--n-envs", "2", "--total-steps", str(TOTAL_STEPS), "--n-steps", "512", "--seed", "1",
              "--env-kwargs", '{"race": {"duration": 20.0}}', "--no-progress", "--force"]


def run_training(tree: Path, options: list[str], out: Path) -> float:
    """Wall time [s] of ``python train/pasta.py OPTIONS --out OUT`` with the scripts and package of ``tree``."""
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "train/pasta.py", *options, "--out", str(out)], cwd=str(tree),
                          env=dict(os.environ, PYTHONPATH=str(tree)), capture_output=True, text=True, check=False)
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        raise RuntimeError(f"training with {' '.join(options)} in {tree} failed:\n{proc.stderr[-4000:]}")
    return wall


WARM_UP_ARGS = ["--n-envs", "2", "--total-steps", "256", "--n-steps", "128", "--seed", "1", "--no-progress", "--force"]
"""A short run made once per side before its first timed run, untimed: an exported revision starts without
numba's cache of compiled kernels, and compiling them would count against that side's first round."""


def warmed(run):
    """``run(side, tree, scratch, round)`` of :func:`bench_compare.interleave`, preceded once per side by an untimed
    :data:`WARM_UP_ARGS` run."""
    done: set[str] = set()

    def call(side, tree, scratch, r):
        if side not in done:
            run_training(tree, WARM_UP_ARGS, scratch / f"warm_up_{side}")
            done.add(side)
        return run(side, tree, scratch, r)
    return call


def time_training(tree: Path, out: Path) -> float:
    """Wall time [s] of the training command of :data:`TRAIN_ARGS` with the scripts and package of ``tree``."""
    return run_training(tree, TRAIN_ARGS, out)


BACKEND_STEPS = 8192
BACKEND_ARGS = ["--total-steps", str(BACKEND_STEPS), "--seed", "1", "--no-progress", "--force"]
BACKENDS = {"one-process": ["--n-envs", "1", "--n-steps", "2048", "--backend", "local"],
            "local": ["--n-envs", "2", "--n-steps", "1024", "--backend", "local"],
            "processes": ["--n-envs", "2", "--n-steps", "1024", "--backend", "processes"],
            "ray": ["--n-envs", "2", "--n-steps", "1024", "--backend", "ray"]}
"""The set-ups of ``--backends``: two envs on each backend of ``train/pasta.py``, and ``one-process``, one env
stepped in the learner's process (rollouts of the same 2048 steps)."""


def collect_time(out: Path) -> float:
    """Seconds the run in ``out`` spent collecting rollouts (the sum of its ``time/collect_s`` scalars)."""
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    files = sorted(out.glob("tb/**/events.out.tfevents.*"))
    if not files:
        raise RuntimeError(f"no TensorBoard log under {out}")
    acc = EventAccumulator(str(files[0]), size_guidance={"scalars": 0})
    acc.Reload()
    return float(sum(e.value for e in acc.Scalars("time/collect_s")))


def time_backend(tree: Path, backend: str, out: Path, extra: list[str] = ()) -> dict:
    """Wall and collection time of :data:`BACKEND_ARGS` with the set-up ``backend`` of :data:`BACKENDS` (and
    the options ``extra``)."""
    wall = run_training(tree, [*BACKEND_ARGS, *BACKENDS[backend], *extra], out)
    return {"wall_s": wall, "collect_s": collect_time(out)}


def compare_backends(backends: list[str], rounds: int, scenario: str | None = None, cars: int | None = None) -> dict:
    """Rounds of one run per backend (the order rotating), and the summary described in the module docstring."""
    import tempfile

    tree = Path(_git(_HERE, "rev-parse", "--show-toplevel"))
    runs: dict[str, list[dict]] = {b: [] for b in backends}
    extra = [] if scenario is None else ["--scenario", scenario]
    if cars is not None:
        extra += ["--multi-agent", "--cars", str(cars)]
    with tempfile.TemporaryDirectory() as scratch:
        for r in range(rounds):
            order = backends[r % len(backends):] + backends[:r % len(backends)]
            for b in order:
                runs[b].append(time_backend(tree, b, Path(scratch) / f"{b}_{r}", extra))
            print(f"  round {r + 1}: " + ", ".join(
                f"{b} {BACKEND_STEPS / runs[b][-1]['collect_s']:.0f} steps/s collecting ({runs[b][-1]['wall_s']:.1f} s)"
                for b in backends), flush=True)
    first = backends[0]
    result = {"command": {b: "python train/pasta.py " + " ".join(BACKEND_ARGS + BACKENDS[b] + extra) + " --out DIR"
                          for b in backends},
              "rounds": rounds, "commit": _git(tree, "rev-parse", "HEAD"), "cpu_count": os.cpu_count(), "backends": {}}
    for b in backends:
        sps = [BACKEND_STEPS / x["collect_s"] for x in runs[b]]
        ratio = [s / (BACKEND_STEPS / f["collect_s"]) for s, f in zip(sps, runs[first])]
        result["backends"][b] = {"wall_s": _summary([x["wall_s"] for x in runs[b]]),
                                 "collect_s": _summary([x["collect_s"] for x in runs[b]]),
                                 "collect_env_steps_per_s": _summary(sps),
                                 f"per_round_ratio_to_{first}": _summary(ratio)}
        m = result["backends"][b]
        print(f"  {b}: {m['collect_env_steps_per_s']['median']:.0f} env steps/s collecting (median), "
              f"{m[f'per_round_ratio_to_{first}']['median']:.2f}x {first} per round "
              f"[{m[f'per_round_ratio_to_{first}']['min']:.2f}, {m[f'per_round_ratio_to_{first}']['max']:.2f}]; "
              f"wall {m['wall_s']['median']:.1f} s")
    return result


def compare_revision_backend(rev: str, backend: str, rounds: int, scenario: str | None) -> dict:
    """Interleaved rounds of the set-up ``backend`` of :data:`BACKENDS` on ``rev`` (old) and the working tree (new):
    wall and collection times per side, and the per-round ratio of the collection rates (new / old)."""
    repo = Path(_git(_HERE, "rev-parse", "--show-toplevel"))
    extra = [] if scenario is None else ["--scenario", scenario]
    old_commit, runs = interleave(
        repo, rev, rounds, warmed(lambda side, tree, scratch, r: time_backend(tree, backend, scratch / f"run_{side}_{r}",
                                                                              extra)),
        lambda old, new: (f"old {BACKEND_STEPS / old['collect_s']:.0f}, new {BACKEND_STEPS / new['collect_s']:.0f} "
                          f"env steps/s collecting ({old['wall_s']:.1f} / {new['wall_s']:.1f} s)"))
    result = {"command": "python train/pasta.py " + " ".join(BACKEND_ARGS + BACKENDS[backend] + extra) + " --out DIR",
              "rounds": rounds, "cpu_count": os.cpu_count(),
              "old": {"rev": rev, "commit": old_commit}, "new": {"rev": "working tree", "commit": _git(repo, "rev-parse", "HEAD")}}
    for side in ("old", "new"):
        result[side].update(wall_s=_summary([x["wall_s"] for x in runs[side]]),
                            collect_env_steps_per_s=_summary([BACKEND_STEPS / x["collect_s"] for x in runs[side]]))
    result["per_round_collect_ratio"] = _summary([o["collect_s"] / n["collect_s"] for o, n in zip(runs["old"], runs["new"])])
    for side in ("old", "new"):
        c = result[side]["collect_env_steps_per_s"]
        print(f"  {side} ({result[side]['commit'][:9]}): {c['median']:.0f} env steps/s collecting, median "
              f"[{c['min']:.0f}, {c['max']:.0f}]; wall {result[side]['wall_s']['median']:.1f} s")
    r = result["per_round_collect_ratio"]
    print(f"  collection new/old per round: {r['median']:.2f}x [{r['min']:.2f}, {r['max']:.2f}]")
    return result


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    mode = parser.add_mutually_exclusive_group(required=True)
    mode.add_argument("--compare", metavar="REV", help="git revision to compare against")
    mode.add_argument("--backends", nargs="+", metavar="B",
                      help="compare these set-ups instead: one-process, local, processes, ray (module docstring)")
    parser.add_argument("--rounds", type=positive_int, default=3,
                        help="rounds of one run per side, alternating (default 3)")
    parser.add_argument("--backend", choices=tuple(BACKENDS), default=None,
                        help="with --compare: time this set-up of --backends on both sides (8192 steps, the "
                             "collection rate from TensorBoard) instead of the short default command")
    parser.add_argument("--scenario", choices=SCENARIOS, default=None,
                        help=f"with --backends, or --compare with --backend: the world trained in, one of "
                             f"{', '.join(SCENARIOS)} (train/pasta.py --scenario; default: its own)")
    parser.add_argument("--multi-agent", type=int_at_least(2), default=None, metavar="CARS",
                        help="with --backends: self-play on races of CARS cars (train/pasta.py --multi-agent --cars "
                             "CARS); --n-envs counts races, the steps car decisions")
    parser.add_argument("--json", default=None, help="also write the results to this JSON file")
    args = parser.parse_args(argv)
    if args.backends is not None:
        unknown = [b for b in args.backends if b not in BACKENDS]
        if unknown or len(set(args.backends)) != len(args.backends) or len(args.backends) < 2:
            parser.error(f"--backends takes two or more distinct values of {', '.join(BACKENDS)}; got {args.backends}")
        if args.backend is not None:
            parser.error("--backend goes with --compare; with --backends every named set-up runs")
        result = compare_backends(args.backends, args.rounds, args.scenario, args.multi_agent)
        if args.json:
            write_json_atomic(args.json, result, trailing_newline=False, indent=2)
        return result
    if args.scenario is not None and args.backend is None:
        parser.error("--scenario with --compare needs --backend (the short default command trains in its own world)")
    if args.backend is not None:
        result = compare_revision_backend(args.compare, args.backend, args.rounds, args.scenario)
        if args.json:
            write_json_atomic(args.json, result, trailing_newline=False, indent=2)
        return result
    repo = Path(_git(_HERE, "rev-parse", "--show-toplevel"))
    old_commit, walls = interleave(repo, args.compare, args.rounds,
                                   warmed(lambda side, tree, scratch, r: time_training(tree, scratch / f"run_{side}_{r}")),
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
        write_json_atomic(args.json, result, trailing_newline=False, indent=2)
    return result


if __name__ == "__main__":
    main()
