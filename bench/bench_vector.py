"""What two workers can give on this host: AsyncVectorEnv throughput against one process, for SOfAR and for a synthetic env.

Usage::

    python bench/bench_vector.py [--workers 2] [--steps 600] [--rounds 3] [--work-ms 1.0]
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
   one process, then an ``AsyncVectorEnv`` of N workers, as in ``bench/bench_env.py --vector``;
4. ``independent``: N processes, each stepping its own env with no messages at all, at the same
   time (they start together after their warm-up, and each stops when the first one is done), for
   the synthetic env and for SOfAR. Their summed throughput is what N workers can give on this host
   under any protocol: above it, no vector env can go;
5. ``lockstep`` (SOfAR, and the synthetic env): the ``AsyncVectorEnv`` run once more with every
   worker's env wrapped in a timer, so that the wall time of one vector step splits into its parts
   (``perf_counter`` is the system-wide monotonic clock on Linux, so the workers' and the main
   process's stamps compare), at the worker that ends last (the lock-step waits for it): the
   dispatch (from the main process's ``step`` call to that worker's start), its step, and the return
   (from its end to ``step`` returning: pickling, merging the infos, copying the observations).

Each row reports env steps per second (all workers together), medians over the rounds, and the
ratio of the vector figure to the one-process figure. If the synthetic env's ratio is already far
below N, the lock-step on this host is the limit, not the env's own cost.
"""

from __future__ import annotations

import argparse
import functools
import multiprocessing as mp
import os
import time

import gymnasium as gym
import numpy as np

from sofar_agents.cli_types import nonneg_int, positive_float, positive_int
from sofar_agents.evaluation.files import write_json_atomic
from sofar_env.vector import async_vector_env, worker_cpus

N_OBS = 12
ACTION = np.array([0.5], np.float32)
"""The action of every single-env pass: gamma 0.5."""


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


def _warmed_up(make, seed: int):
    """A new env of ``make``, reset with ``seed`` and stepped 20 times (SOfAR builds and loads its controllers)."""
    env = make()
    env.reset(seed=seed)
    for _ in range(20):
        env.step(ACTION)
    return env


def _time_steps(env, steps: int, stop=None) -> tuple[int, float, float]:
    """Steps ``env`` ``steps`` times (or until ``stop`` is set), resetting it when an episode ends; returns the steps
    made, their wall time and their CPU time [s] (resets excluded)."""
    counted, elapsed, cpu = 0, 0.0, 0.0
    while counted < steps and not (stop is not None and stop.is_set()):
        t0, c0 = time.perf_counter(), time.thread_time()
        _, _, terminated, truncated, _ = env.step(ACTION)
        cpu += time.thread_time() - c0
        elapsed += time.perf_counter() - t0
        counted += 1
        if terminated or truncated:
            env.reset()
    return counted, elapsed, cpu


def one_process(make, steps: int, seed: int = 0, cpu_ms: list | None = None) -> float:
    """Env steps/s of one env stepped in this process (resets excluded from the count); the mean CPU time of a
    step [ms] is appended to ``cpu_ms`` if given."""
    env = _warmed_up(make, seed)
    counted, elapsed, cpu = _time_steps(env, steps)
    env.close()
    if cpu_ms is not None:
        cpu_ms.append(1e3 * cpu / counted)
    return counted / elapsed


def vector(make, workers: int, steps: int, seed: int = 0, pin: bool = False) -> float:
    """Env steps/s of an ``AsyncVectorEnv`` of ``workers`` processes (steps that only reset excluded); ``pin``: each
    worker on a CPU of its own (:func:`sofar_env.vector.async_vector_env`)."""
    envs = async_vector_env([make] * workers, pin_workers=pin)
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


def _independent_worker(make, steps: int, seed: int, ready, stop, results) -> None:
    """One of :func:`independent`'s processes: warm up, wait for the others, step until done or told to stop."""
    env = _warmed_up(make, seed)
    ready.wait()
    counted, elapsed, _ = _time_steps(env, steps, stop)
    stop.set()  # the overlap ends with the first process done: the others would then run alone
    results.put(counted / elapsed)
    env.close()


def independent(make, workers: int, steps: int, seed: int = 0) -> float:
    """Summed env steps/s of ``workers`` processes each stepping its own env at the same time, with no messages
    between them (module docstring, item 4)."""
    ctx = mp.get_context("spawn")
    ready, stop, results = ctx.Barrier(workers), ctx.Event(), ctx.Queue()
    procs = [ctx.Process(target=_independent_worker, args=(make, steps, seed + i, ready, stop, results), daemon=True)
             for i in range(workers)]
    for p in procs:
        p.start()
    try:
        rates = [results.get(timeout=600) for _ in range(workers)]
    finally:
        for p in procs:
            p.join(timeout=30)
    return float(sum(rates))


class StepTimer(gym.Wrapper):
    """Records, for every ``step`` and ``reset`` of the env it wraps, the ``perf_counter`` stamps around it and
    the CPU time this thread spent in it (for :func:`lockstep`)."""

    def __init__(self, env: gym.Env):
        super().__init__(env)
        self.stamps: list[tuple[float, float, float]] = []

    def _timed_call(self, fn, *args, **kwargs):
        t0, c0 = time.perf_counter(), time.thread_time()
        out = fn(*args, **kwargs)
        c1, t1 = time.thread_time(), time.perf_counter()
        self.stamps.append((t0, t1, c1 - c0))
        return out

    def step(self, action):
        return self._timed_call(self.env.step, action)

    def reset(self, **kwargs):
        return self._timed_call(self.env.reset, **kwargs)

    def clear_stamps(self) -> None:
        self.stamps = []

    def get_stamps(self) -> np.ndarray:
        return np.array(self.stamps, dtype=float).reshape(-1, 3)


def _timed(make):
    return StepTimer(make())


def split_lockstep(calls: np.ndarray, stamps: list[np.ndarray]) -> dict:
    """Mean parts of one vector step [ms] from the main process's (K, 2) ``step`` call/return stamps and
    every worker's (K, 2) start/end stamps of its env's ``step`` or ``reset`` (one per vector step), or (K, 3)
    with the CPU time the worker's thread spent in it as third column.

    A vector step is split at the worker that ends last: ``vector_step = dispatch + last_worker_step + return``
    (the call to that worker's start, its step, its end to the return), exactly. Also given: the mean step
    of all workers and the mean of the slowest one's, and with CPU times, their mean (``worker_cpu_ms``): a
    step whose wall time exceeds its CPU time waited for a CPU; one whose CPU time grew ran slower."""
    starts = np.stack([s[:, 0] for s in stamps])  # (workers, K)
    ends = np.stack([s[:, 1] for s in stamps])
    work = ends - starts
    cols = np.arange(starts.shape[1])
    last = ends.argmax(axis=0)
    ms = 1e3
    return {
        "vector_step_ms": float(np.mean(calls[:, 1] - calls[:, 0]) * ms),
        "dispatch_ms": float(np.mean(starts[last, cols] - calls[:, 0]) * ms),
        "last_worker_step_ms": float(np.mean(work[last, cols]) * ms),
        "return_ms": float(np.mean(calls[:, 1] - ends[last, cols]) * ms),
        "worker_step_ms": float(np.mean(work) * ms),
        "slowest_worker_step_ms": float(np.mean(work.max(axis=0)) * ms),
    } | ({"worker_cpu_ms": float(np.mean([s[:, 2] for s in stamps]) * ms)} if stamps[0].shape[1] > 2 else {})


def lockstep(make, workers: int, steps: int, seed: int = 0, pin: bool = False) -> dict:
    """The parts of an ``AsyncVectorEnv`` step (module docstring, item 5), means over ``steps`` vector steps [ms],
    and the throughputs they bound: ``workers`` over the mean worker step (no waiting, no protocol) and over the
    mean slowest worker step (the lock-step's wait, no protocol)."""
    envs = async_vector_env([functools.partial(_timed, make)] * workers, pin_workers=pin)
    try:
        actions = np.full((workers, 1), 0.5, np.float32)
        envs.reset(seed=[seed + i for i in range(workers)])
        for _ in range(20):
            envs.step(actions)
        envs.call("clear_stamps")
        calls = np.empty((steps, 2))
        for k in range(steps):
            calls[k, 0] = time.perf_counter()
            envs.step(actions)
            calls[k, 1] = time.perf_counter()
        parts = split_lockstep(calls, list(envs.call("get_stamps")))
    finally:
        envs.close()
    parts["bound_no_wait_steps_per_s"] = 1e3 * workers / parts["worker_step_ms"]
    parts["bound_lockstep_steps_per_s"] = 1e3 * workers / parts["slowest_worker_step_ms"]
    return parts


def _median_row(values: list[float], singles: list[float]) -> dict:
    ratios = [v / s for v, s in zip(values, singles)]
    return {"steps_per_s": float(np.median(values)), "per_round": [float(v) for v in values],
            "ratio_to_one_process": float(np.median(ratios)), "ratio_per_round": [float(r) for r in ratios]}


def _median_split(rounds: list[dict]) -> dict:
    """Per key of :func:`lockstep`'s dicts, the median over the rounds (and the per-round values)."""
    return {k: float(np.median([r[k] for r in rounds])) for k in rounds[0]} | {"per_round": rounds}


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--workers", type=positive_int, default=2,
                        help="worker processes of the vector env (default 2)")
    parser.add_argument("--steps", type=positive_int, default=600,
                        help="timed vector steps per measurement (default 600)")
    parser.add_argument("--rounds", type=positive_int, default=3, help="rounds of every measurement (default 3)")
    parser.add_argument("--work-ms", type=positive_float, default=1.0,
                        help="CPU time of one synthetic step [ms] (default 1.0, about one SOfAR step)")
    parser.add_argument("--info-keys", type=nonneg_int, default=18,
                        help="scalars in the synthetic info dict (default 18, as many as SOfAR's)")
    parser.add_argument("--no-sofar", action="store_true", help="only the synthetic env and the bare pipes")
    parser.add_argument("--json", default=None, help="also write the results to this JSON file")
    args = parser.parse_args(argv)

    synthetic = functools.partial(SyntheticEnv, work_ms=args.work_ms, info_keys=args.info_keys)
    envs = {"synthetic": synthetic} if args.no_sofar else {"synthetic": synthetic, "sofar": _sofar_env}
    pins = (False, True) if worker_cpus(args.workers) is not None else (False,)
    n, steps = args.workers, args.steps
    rates: dict[str, list[float]] = {}
    cpu_one: dict[str, list[float]] = {}  # CPU time of a step in one process [ms], per round
    splits: dict[str, list[dict]] = {}
    for r in range(args.rounds):
        for name, make in envs.items():
            rates.setdefault(f"{name}_one_process", []).append(
                one_process(make, steps, cpu_ms=cpu_one.setdefault(name, [])))
            for pin in pins:
                suffix = "_pinned" if pin else ""
                rates.setdefault(f"{name}_async_vector{suffix}", []).append(vector(make, n, steps, pin=pin))
                splits.setdefault(f"{name}_lockstep{suffix}", []).append(lockstep(make, n, steps, pin=pin))
            if name == "synthetic":
                rates.setdefault("synthetic_bare_pipes", []).append(pipe(n, steps, args.work_ms))
            rates.setdefault(f"{name}_independent", []).append(independent(make, n, steps))
        print(f"round {r + 1}/{args.rounds}: " + ", ".join(f"{k} {v[-1]:.0f}" for k, v in rates.items()), flush=True)

    result: dict = {"workers": n, "steps": steps, "rounds": args.rounds, "work_ms": args.work_ms,
                    "info_keys": args.info_keys, "cpu_count": os.cpu_count(), "pinned_cpus": worker_cpus(n)}
    for key, values in rates.items():
        result[key] = _median_row(values, rates[key.split("_")[0] + "_one_process"])
    for name, values in cpu_one.items():
        result[f"{name}_one_process"]["cpu_ms_per_step"] = float(np.median(values))
    for key, rounds in splits.items():
        result[key] = _median_split(rounds)
    print(f"{n} workers, {args.rounds} rounds of {steps} steps; medians, env steps/s (ratio to one process)")
    for key in rates:
        row = result[key]
        print(f"  {key:30s} {row['steps_per_s']:8.0f}  ({row['ratio_to_one_process']:.2f}x)")
    for name in envs:
        if f"{name}_async_vector_pinned" in rates:
            ratios = [p / u for p, u in zip(rates[f"{name}_async_vector_pinned"], rates[f"{name}_async_vector"])]
            result[f"{name}_pinned_over_unpinned"] = {"median": float(np.median(ratios)), "per_round": ratios}
            print(f"  {name}: pinned over unpinned, per round: median {np.median(ratios):.2f}x "
                  f"[{min(ratios):.2f}, {max(ratios):.2f}]")
    print("AsyncVectorEnv step, ms (medians of the rounds' means) = dispatch + last worker's step + return; "
          "one process: " + ", ".join(f"{name} {result[f'{name}_one_process']['cpu_ms_per_step']:.3f} ms of CPU per step"
                                      for name in envs))
    for key in splits:
        row = result[key]
        print(f"  {key:30s} {row['vector_step_ms']:.3f} = {row['dispatch_ms']:.3f} + {row['last_worker_step_ms']:.3f}"
              f" + {row['return_ms']:.3f}; worker step: mean {row['worker_step_ms']:.3f} "
              f"(CPU {row['worker_cpu_ms']:.3f}), slowest {row['slowest_worker_step_ms']:.3f}")
    if args.json:
        write_json_atomic(args.json, result, trailing_newline=False, indent=2)
    return result


if __name__ == "__main__":
    main()
