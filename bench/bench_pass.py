"""One timed pass of a SOfAR environment made through its public constructor: a side of ``bench_env.py --compare``.

Usage::

    python bench/bench_pass.py --env-id SOfAR-LagunaSeca-v0 --kwargs '{"rho": 0.5, "n_opponents": 4}'
                              [--steps 300] [--gamma 0.5] [--seed 0] [--warm-up 20] [--vector N] [--json PATH]

The environment is made with ``gymnasium.make(ENV_ID, **KWARGS)`` after ``import sofar_env`` (which registers
the ids) and driven with a constant gamma; nothing else of the package is imported, so the same script runs
against any revision whose ``sofar_env`` registers the id and accepts the keyword arguments (the revision is
chosen by ``PYTHONPATH``; the JSON records which ``sofar_env`` was imported). After ``--warm-up`` untimed steps
(the controllers are built, and compiled code loaded or compiled, on the first ones), ``--steps`` steps from a
seeded reset are timed one by one, resets excluded, with the wall clock (``time.perf_counter``) and with the
CPU time of this process (``time.process_time``: every thread of the process, user and system). On a host
shared with other work the CPU time per step is the steadier figure: other load stretches the wall time of a
step while its CPU time stays about the same.

The host's 1-minute load average and the time of a fixed reference workload (independent of the package)
are recorded before and after the pass.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import math
import os
import sys
import time

import numpy as np


def reference_workload_ms(repeats: int = 5) -> float:
    """Best-of-``repeats`` wall time [ms] of a fixed CPU-bound workload shaped like the env's hot path
    (scalar Python float arithmetic and numpy calls on small arrays).

    It does not depend on the package, so it measures the host, not the code: on a shared or
    virtual machine the same binary runs slower while other tenants load the physical cores, and
    the env's steps/s fall by about the factor this time rises. Reported next to the steps/s so that
    runs on differently loaded hosts can be compared.
    """
    rng = np.random.default_rng(0)
    a = rng.standard_normal(76)
    b = rng.standard_normal((76, 6))
    best = math.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        x = 0.0
        for i in range(20000):  # scalar float work, as in the track's and opponents' scalar paths
            x = (x * 0.5 + i * 1e-3) % 7.0
        for _ in range(2000):  # small-array numpy calls, as in the planners' glue
            c = np.maximum(a, 0.0) * 2.0 - a
            x += float(c.sum()) + float((b @ b[0]).min())
        best = min(best, time.perf_counter() - t0)
    return 1e3 * best


def load_average() -> float | None:
    """The host's 1-minute load average (None where the OS has none): a busy host slows every pass."""
    try:
        return float(os.getloadavg()[0])
    except (AttributeError, OSError):
        return None


def timed_steps(env, steps: int, gamma: float, seed: int) -> dict:
    """Wall and CPU time of ``steps`` steps of ``env`` at constant ``gamma`` from ``reset(seed=seed)`` (resets
    excluded; an episode that ends is reset with the next seed), and ``trajectory_digest``: the SHA-256 of
    every step's observation and reward (float64 bytes) and of the reset observations, computed outside the
    timed region. Two passes with the same digest drove the same trajectory to the bit (same observation
    layout assumed: a revision with another layout gives another digest)."""
    action = np.array([gamma], np.float32)
    digest = hashlib.sha256()

    def record(obs, reward=None):
        digest.update(np.asarray(obs, np.float64).tobytes())
        if reward is not None:
            digest.update(np.asarray(reward, np.float64).tobytes())

    record(env.reset(seed=seed)[0])
    wall, cpu = np.empty(steps), np.empty(steps)
    mpc = []
    episodes = 0
    perf, proc = time.perf_counter, time.process_time
    for i in range(steps):
        c0, t0 = proc(), perf()
        obs, reward, terminated, truncated, info = env.step(action)
        t1, c1 = perf(), proc()
        wall[i], cpu[i] = t1 - t0, c1 - c0
        record(obs, reward)
        if "mpc_time_ms" in info:
            mpc.append(info["mpc_time_ms"])
        if terminated or truncated:
            episodes += 1
            record(env.reset(seed=seed + episodes)[0])
    return {
        "steps": steps, "episodes_ended": episodes,
        "wall_s": float(wall.sum()), "cpu_s": float(cpu.sum()),
        "steps_per_s": steps / float(wall.sum()),
        "wall_ms_per_step": 1e3 * float(wall.mean()), "cpu_ms_per_step": 1e3 * float(cpu.mean()),
        "step_ms": {"median": 1e3 * float(np.median(wall)), "p95": 1e3 * float(np.percentile(wall, 95)),
                    "mean": 1e3 * float(wall.mean())},
        "mpc_median_ms": float(np.median(mpc)) if mpc else None,
        "trajectory_digest": digest.hexdigest(),
    }


def timed_vector(env_id: str, kwargs: dict, n: int, steps: int, gamma: float, seed: int) -> dict:
    """Total env steps/s of a gymnasium ``AsyncVectorEnv`` of ``n`` workers, each ``gymnasium.make(env_id, **kwargs)``
    (:func:`timed_async`)."""
    import functools

    import gymnasium as gym

    return timed_async(functools.partial(gym.make, env_id, **kwargs), n, steps, gamma, seed)


def timed_async(factory, n: int, steps: int, gamma: float, seed: int, pin: bool = True) -> dict:
    """Total env steps/s of a gymnasium ``AsyncVectorEnv`` of ``n`` workers built by ``factory``, seeded
    ``seed + i``, over ``steps`` vector steps after 20 untimed ones (steps that only reset not counted). With
    ``pin`` the workers are pinned to a CPU each where the package has :mod:`sofar_env.vector` (older
    revisions did not pin)."""
    import gymnasium as gym

    try:
        from sofar_env.vector import pinned_factories, worker_cpus
    except ImportError:
        fns, pinned = [factory] * n, False
    else:
        pinned = pin and worker_cpus(n) is not None
        fns = pinned_factories([factory] * n, pin=pinned)
    envs = gym.vector.AsyncVectorEnv(fns)
    try:
        actions = np.full((n, 1), gamma, np.float32)
        envs.reset(seed=[seed + i for i in range(n)])
        for _ in range(20):  # warm-up: the workers build (and load) their controllers
            envs.step(actions)
        counted, episodes, resetting = 0, 0, np.zeros(n, bool)
        t0 = time.perf_counter()
        for _ in range(steps):
            _, _, terminated, truncated, _ = envs.step(actions)
            counted += int(n - resetting.sum())
            resetting = terminated | truncated
            episodes += int(resetting.sum())
        wall = time.perf_counter() - t0
    finally:
        envs.close()
    return {"workers": n, "pinned": pinned, "vector_steps": steps, "env_steps": counted, "wall_s": wall,
            "steps_per_s": counted / wall, "episodes_ended": episodes}


def _count(least: int):
    """An argument type: an integer >= ``least`` (this script cannot use the package's argument types: it runs
    against revisions without them)."""
    def parse(text: str) -> int:
        value = int(text)
        if value < least:
            raise argparse.ArgumentTypeError(f"must be an integer >= {least}, got {text}")
        return value
    parse.__name__ = f"integer >= {least}"
    return parse


def _finite(text: str) -> float:
    value = float(text)
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"must be a finite number, got {text}")
    return value


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--env-id", default="SOfAR-LagunaSeca-v0", help="a registered id (default SOfAR-LagunaSeca-v0)")
    parser.add_argument("--kwargs", default="{}", help="keyword arguments of gymnasium.make, as a JSON object")
    parser.add_argument("--steps", type=_count(1), default=300, help="timed steps (default 300)")
    parser.add_argument("--gamma", type=_finite, default=0.5, help="the constant action (default 0.5)")
    parser.add_argument("--seed", type=_count(0), default=0)
    parser.add_argument("--warm-up", type=_count(0), default=20, help="untimed steps before the timed ones (default 20)")
    parser.add_argument("--vector", type=_count(0), default=0, metavar="N",
                        help="also time an AsyncVectorEnv of N workers (default 0: not)")
    parser.add_argument("--json", default=None, help="also write the result to this JSON file")
    args = parser.parse_args(argv)
    kwargs = json.loads(args.kwargs)
    if not isinstance(kwargs, dict):
        parser.error("--kwargs must be a JSON object")

    import gymnasium as gym

    import sofar_env  # registers the ids

    load_before, ref_before = load_average(), reference_workload_ms()
    env = gym.make(args.env_id, **kwargs)
    env.reset(seed=args.seed)
    action = np.array([args.gamma], np.float32)
    for _ in range(args.warm_up):
        env.step(action)
    result = timed_steps(env, args.steps, args.gamma, args.seed)
    env.close()
    ref_after, load_after = reference_workload_ms(), load_average()
    result.update({
        "env_id": args.env_id, "kwargs": kwargs, "gamma": args.gamma, "seed": args.seed, "warm_up": args.warm_up,
        "package": os.path.dirname(os.path.abspath(sofar_env.__file__)),
        "cpu_count": os.cpu_count(),
        "load_average_1min": {"before": load_before, "after": load_after},
        "reference_workload_ms": {"before": ref_before, "after": ref_after},
    })
    if args.vector:
        result["vector"] = timed_vector(args.env_id, kwargs, args.vector, args.steps, args.gamma, args.seed)
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(result, fh, indent=2)
    print(f"{args.env_id} {json.dumps(kwargs)}: {result['cpu_ms_per_step']:.3f} ms CPU, "
          f"{result['wall_ms_per_step']:.3f} ms wall per step ({args.steps} steps; sofar_env from {result['package']})")
    return result


if __name__ == "__main__":
    sys.exit(0 if main() else 1)
