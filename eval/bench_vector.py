"""What two workers can give on this host: AsyncVectorEnv throughput against one process, for SOfAR and for a synthetic env.

Usage::

    python eval/bench_vector.py [--workers 2] [--steps 600] [--rounds 3] [--work-ms 1.0]
                                [--info-keys 18] [--no-sofar] [--json PATH]

A vector env of N workers steps in lock-step: the main process sends every worker its action,
waits for every answer, merges the answers and only then sends the next actions. Its throughput
against one process is therefore bounded by the host and by that protocol, whatever the env.
This script separates the two. Each round measures, in this order:

1. ``synthetic``: an env whose ``step`` burns ``--work-ms`` of CPU time (a fixed busy loop, no
   I/O) and returns an info dict of ``--info-keys`` scalars, as SOfAR's does: one process, then a
   gymnasium ``AsyncVectorEnv`` of N workers;
2. ``pipe``: the same work in N bare ``multiprocessing`` workers driven over pipes in the same
   lock-step (send N requests, wait for N replies), without gymnasium's pickling of actions,
   shared-memory observations and info merging;
3. ``sofar`` (unless ``--no-sofar``): ``SOfAR-LagunaSeca-v0`` (4 opponents, rho 0.5, gamma 0.5):
   one process, then an ``AsyncVectorEnv`` of N workers, as in ``eval/bench_env.py --vector``.

Each row reports env steps per second (all workers together), medians over the rounds, and the
ratio of the vector figure to the one-process figure. If the synthetic env's ratio is already far
below N, the lock-step on this host is the limit, not the env's own cost.
"""

from __future__ import annotations

import argparse
import functools
import json
import multiprocessing as mp
import os
import time

import gymnasium as gym
import numpy as np

N_OBS = 12


def burn(work_s: float) -> None:
    """Spend ``work_s`` seconds of this thread's CPU time in a busy loop."""
    end = time.thread_time() + work_s
    while time.thread_time() < end:
        pass


class SyntheticEnv(gym.Env):
    """A stand-in env whose step costs a fixed CPU time and answers like SOfAR's (12 floats, info of scalars)."""

    def __init__(self, work_ms: float = 1.0, info_keys: int = 18):
        self.observation_space = gym.spaces.Box(-np.inf, np.inf, (N_OBS,), np.float32)
        self.action_space = gym.spaces.Box(0.05, 1.0, (1,), np.float32)
        self._work_s = 1e-3 * work_ms
        self._keys = [f"k{i}" for i in range(info_keys)]

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        return np.zeros(N_OBS, np.float32), {}

    def step(self, action):
        burn(self._work_s)
        return np.zeros(N_OBS, np.float32), 0.0, False, False, {k: 0.0 for k in self._keys}


def _sofar_env():
    from sofar_env.env import SOfARRaceEnv

    return SOfARRaceEnv(track="LagunaSeca", rho=0.5, n_opponents=4)


def one_process(make, steps: int, seed: int = 0) -> float:
    """Env steps/s of one env stepped in this process (resets excluded from the count)."""
    env = make()
    env.reset(seed=seed)
    action = np.array([0.5], np.float32)
    for _ in range(20):  # warm-up (SOfAR builds and loads its controllers)
        env.step(action)
    counted, elapsed = 0, 0.0
    for _ in range(steps):
        t0 = time.perf_counter()
        _, _, terminated, truncated, _ = env.step(action)
        elapsed += time.perf_counter() - t0
        counted += 1
        if terminated or truncated:
            env.reset()
    env.close()
    return counted / elapsed


def vector(make, workers: int, steps: int, seed: int = 0) -> float:
    """Env steps/s of an ``AsyncVectorEnv`` of ``workers`` processes (steps that only reset excluded)."""
    envs = gym.vector.AsyncVectorEnv([make] * workers)
    try:
        actions = np.full((workers, 1), 0.5, np.float32)
        envs.reset(seed=[seed + i for i in range(workers)])
        for _ in range(20):
            envs.step(actions)
        counted, resetting = 0, np.zeros(workers, bool)
        t0 = time.perf_counter()
        for _ in range(steps):
            _, _, terminated, truncated, _ = envs.step(actions)
            counted += int(workers - resetting.sum())
            resetting = terminated | truncated
        return counted / (time.perf_counter() - t0)
    finally:
        envs.close()


def _pipe_worker(conn, work_s: float) -> None:
    while conn.recv_bytes() != b"q":
        burn(work_s)
        conn.send_bytes(b"x")


def pipe(workers: int, steps: int, work_ms: float) -> float:
    """Work items/s of ``workers`` bare processes doing ``work_ms`` of CPU per request, in lock-step over pipes."""
    ctx = mp.get_context("spawn")  # what AsyncVectorEnv uses by default where fork is unsafe; one start-up cost
    pipes = [ctx.Pipe() for _ in range(workers)]
    procs = [ctx.Process(target=_pipe_worker, args=(child, 1e-3 * work_ms), daemon=True) for _, child in pipes]
    for p in procs:
        p.start()
    try:
        def round_trip():
            for parent, _ in pipes:
                parent.send_bytes(b"s")
            for parent, _ in pipes:
                parent.recv_bytes()

        for _ in range(20):
            round_trip()
        t0 = time.perf_counter()
        for _ in range(steps):
            round_trip()
        return workers * steps / (time.perf_counter() - t0)
    finally:
        for parent, _ in pipes:
            parent.send_bytes(b"q")
        for p in procs:
            p.join(timeout=10)


def _median_row(values: list[float], singles: list[float]) -> dict:
    ratios = [v / s for v, s in zip(values, singles)]
    return {"steps_per_s": float(np.median(values)), "per_round": [float(v) for v in values],
            "ratio_to_one_process": float(np.median(ratios)), "ratio_per_round": [float(r) for r in ratios]}


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--workers", type=int, default=2, help="worker processes of the vector env (default 2)")
    parser.add_argument("--steps", type=int, default=600, help="timed vector steps per measurement (default 600)")
    parser.add_argument("--rounds", type=int, default=3, help="rounds of every measurement (default 3)")
    parser.add_argument("--work-ms", type=float, default=1.0,
                        help="CPU time of one synthetic step [ms] (default 1.0, about one SOfAR step)")
    parser.add_argument("--info-keys", type=int, default=18,
                        help="scalars in the synthetic info dict (default 18, as many as SOfAR's)")
    parser.add_argument("--no-sofar", action="store_true", help="only the synthetic env and the bare pipes")
    parser.add_argument("--json", default=None, help="also write the results to this JSON file")
    args = parser.parse_args(argv)
    for name in ("workers", "steps", "rounds"):
        if getattr(args, name) < 1:
            parser.error(f"--{name.replace('_', '-')} must be >= 1, got {getattr(args, name)}")
    if not args.work_ms > 0:
        parser.error(f"--work-ms must be > 0, got {args.work_ms}")
    if args.info_keys < 0:
        parser.error(f"--info-keys must be >= 0, got {args.info_keys}")

    synthetic = functools.partial(SyntheticEnv, work_ms=args.work_ms, info_keys=args.info_keys)
    runs: dict[str, list[float]] = {k: [] for k in ("synthetic_one", "synthetic_vector", "pipe",
                                                    "sofar_one", "sofar_vector")}
    for r in range(args.rounds):
        runs["synthetic_one"].append(one_process(synthetic, args.steps))
        runs["synthetic_vector"].append(vector(synthetic, args.workers, args.steps))
        runs["pipe"].append(pipe(args.workers, args.steps, args.work_ms))
        if not args.no_sofar:
            runs["sofar_one"].append(one_process(_sofar_env, args.steps))
            runs["sofar_vector"].append(vector(_sofar_env, args.workers, args.steps))
        print(f"round {r + 1}/{args.rounds}: " + ", ".join(f"{k} {v[-1]:.0f}" for k, v in runs.items() if v),
              flush=True)

    result = {
        "workers": args.workers, "steps": args.steps, "rounds": args.rounds, "work_ms": args.work_ms,
        "info_keys": args.info_keys, "cpu_count": os.cpu_count(),
        "synthetic_one_process": _median_row(runs["synthetic_one"], runs["synthetic_one"]),
        "synthetic_async_vector": _median_row(runs["synthetic_vector"], runs["synthetic_one"]),
        "synthetic_bare_pipes": _median_row(runs["pipe"], runs["synthetic_one"]),
    }
    if not args.no_sofar:
        result["sofar_one_process"] = _median_row(runs["sofar_one"], runs["sofar_one"])
        result["sofar_async_vector"] = _median_row(runs["sofar_vector"], runs["sofar_one"])
    print(f"{args.workers} workers, {args.rounds} rounds of {args.steps} steps; medians, env steps/s (ratio to one process)")
    for name in ("synthetic_one_process", "synthetic_async_vector", "synthetic_bare_pipes",
                 "sofar_one_process", "sofar_async_vector"):
        if name in result:
            row = result[name]
            print(f"  {name:24s} {row['steps_per_s']:8.0f}  ({row['ratio_to_one_process']:.2f}x)")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(result, fh, indent=2)
    return result


if __name__ == "__main__":
    main()
