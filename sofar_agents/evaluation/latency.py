"""The paper's Table III: MPC, MIQP and policy latency timed in a closed loop, and its report."""

from __future__ import annotations

import importlib.metadata
import math
import os
import platform
import sys
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from sofar_agents.evaluation.episode import _info_scalar, make_env
from sofar_agents.evaluation.files import write_json_atomic
from sofar_agents.evaluation.protocol import _limit_torch_threads, resolve_policy_path

PAPER_LATENCY_MS = {"mpc_ms": (1.60, 0.34), "miqp_ms": (5.49, 1.73), "rl_ms": (0.82, 0.12)}
"""Paper Table III, mean and std [ms] on an Intel i7-12700H."""


def latency_stats(samples_ms: Sequence[float]) -> dict[str, float]:
    """mean, std (population), median, p95 and count of a list of times [ms]."""
    a = np.asarray(list(samples_ms), float)
    if a.size == 0:
        return {"mean": math.nan, "std": math.nan, "median": math.nan, "p95": math.nan, "n": 0}
    return {"mean": float(a.mean()), "std": float(a.std()), "median": float(np.median(a)),
            "p95": float(np.percentile(a, 95)), "n": int(a.size)}


def machine_info() -> dict[str, Any]:
    """CPU, core count and library versions, for the latency report."""
    cpu = platform.processor() or ""
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    info: dict[str, Any] = {"cpu": cpu, "cores": os.cpu_count(), "platform": platform.platform(),
                            "python": sys.version.split()[0]}
    for dist in ("numpy", "casadi", "piqp", "daqp", "torch", "gymnasium"):
        try:  # the installed distribution's version (daqp's module has no __version__)
            info[dist] = importlib.metadata.version(dist)
        except importlib.metadata.PackageNotFoundError:
            info[dist] = None
    return info


class _TorchMLP:
    """Stand-in policy when no trained one is shipped: 12 -> 256 -> 256 -> 1, tanh (the paper's size)."""

    def __init__(self, n_obs: int, seed: int = 0) -> None:
        import torch

        torch.manual_seed(seed)
        self._torch = torch
        self.net = torch.nn.Sequential(torch.nn.Linear(n_obs, 256), torch.nn.Tanh(), torch.nn.Linear(256, 256),
                                       torch.nn.Tanh(), torch.nn.Linear(256, 1)).eval()

    def __call__(self, obs) -> np.ndarray:
        torch = self._torch
        with torch.no_grad():
            x = torch.as_tensor(np.asarray(obs, np.float32)).reshape(1, -1)
            y = torch.sigmoid(self.net(x))[0]
        return 0.05 + 0.95 * y.numpy().astype(np.float32)


def measure_latency(seconds: float = 60.0, policy: str | os.PathLike | None = None, track: str = "LagunaSeca",
                    rho: float = 0.3, n_opponents: int = 4, fixed_gamma: float = 0.5, seed: int = 0,
                    rl_samples: int = 2000) -> dict[str, Any]:
    """Table III from a closed loop: MPC, MIQP (steps where it ran) and policy inference times [ms].

    The environment (decision interval 1) runs ``seconds`` of simulated time, restarting after a
    collision or leaving the track. gamma comes from the policy (``policy`` or the shipped one); when
    there is none the loop uses ``fixed_gamma`` and the RL time is that of an untrained 2 x 256 tanh MLP
    on the observation, labelled as such. The policy is additionally timed on ``rl_samples`` recorded
    observations after the loop (warm caches, as a deployed node would run it).
    """
    path = resolve_policy_path(policy, fallback=f"gamma is fixed at {fixed_gamma:g} and the RL time is that of an "
                                                 "untrained 2 x 256 tanh MLP")
    _limit_torch_threads()
    # the MPC and MIQP solve times are read from info, which holds them only with timing_info
    env = make_env(track, True, max(float(seconds), 1.0) + 10.0, decision_interval=1, timing_info=True)
    if path is not None:
        from sofar_agents import load_policy

        pol = load_policy(str(path))
        rl_label = f"policy {Path(path).name}"
    else:
        pol = None
        rl_label = "untrained 2x256 tanh MLP (torch; no shipped policy)"
    mpc, miqp, rl, ctrl, env_step, observations = [], [], [], [], [], []
    options = {"rho": float(rho), "n_opponents": int(n_opponents)}
    obs, info = env.reset(seed=seed, options=options)
    mlp = _TorchMLP(int(np.asarray(obs).size), seed) if pol is None else None
    timed = pol if pol is not None else mlp
    for _ in range(20):  # warm-up: first calls allocate
        timed(obs)
    sim = prev = 0.0
    episodes = 1
    try:
        while sim < seconds:
            t0 = time.perf_counter()
            g = timed(obs)
            rl.append((time.perf_counter() - t0) * 1e3)
            observations.append(np.array(obs, copy=True))
            action = np.asarray(g, np.float32).reshape(1) if pol is not None else np.array([fixed_gamma], np.float32)
            t0 = time.perf_counter()
            obs, _, terminated, truncated, info = env.step(action)
            env_step.append((time.perf_counter() - t0) * 1e3)
            m = _info_scalar(info, "mpc_time_ms", math.nan)
            q = _info_scalar(info, "miqp_time_ms", 0.0)
            if math.isfinite(m):
                mpc.append(m)
                ctrl.append(m + (q if math.isfinite(q) else 0.0))
            if math.isfinite(q) and q > 0.0:
                miqp.append(q)
            now = _info_scalar(info, "sim_time", prev + 0.1)
            sim += max(now - prev, 1e-3)
            prev = now
            if terminated or truncated:
                obs, info = env.reset(seed=seed + episodes, options=options)
                prev = 0.0
                episodes += 1
    finally:
        env.close()
    loop_rl = list(rl)
    rl_offline = []
    for i in range(min(rl_samples, 20 * len(observations)) if observations else 0):
        o = observations[i % len(observations)]
        t0 = time.perf_counter()
        timed(o)
        rl_offline.append((time.perf_counter() - t0) * 1e3)
    return {
        "mpc_ms": latency_stats(mpc),
        "miqp_ms": latency_stats(miqp),
        "rl_ms": latency_stats(rl_offline or loop_rl),
        "rl_in_loop_ms": latency_stats(loop_rl),
        "controller_step_ms": latency_stats(ctrl),
        "env_step_ms": latency_stats(env_step),
        "rl_source": rl_label,
        "gamma_source": rl_label if pol is not None else f"fixed gamma = {fixed_gamma:g}",
        "setup": {"track": track, "rho": rho, "n_opponents": n_opponents, "sim_seconds": seconds,
                  "control_steps": len(env_step), "episodes": episodes, "seed": seed},
        "paper_ms": {k: {"mean": m, "std": s} for k, (m, s) in PAPER_LATENCY_MS.items()},
        "machine": machine_info(),
    }


def format_latency(report: Mapping[str, Any]) -> str:
    """Markdown: our mean +- std, median and p95 next to the paper's Table III, with ratios."""
    rows = [("MPC", "mpc_ms"), ("MIQP (steps where it ran)", "miqp_ms"),
            (f"RL ({report.get('rl_source', '')})", "rl_ms"),
            ("Controller step (MPC + MIQP)", "controller_step_ms"), ("Whole env step", "env_step_ms")]
    lines = ["| Component | mean ± std [ms] | median [ms] | p95 [ms] | samples | paper [ms] | ratio (this / paper) |",
             "|---|---:|---:|---:|---:|---:|---:|"]
    for name, key in rows:
        s = report.get(key)
        if not s:
            continue
        paper = PAPER_LATENCY_MS.get(key)
        p_text = f"{paper[0]:.2f} ± {paper[1]:.2f}" if paper else "–"
        ratio = f"{s['mean'] / paper[0]:.2f}" if paper and math.isfinite(s["mean"]) else "–"
        lines.append(f"| {name} | {s['mean']:.3f} ± {s['std']:.3f} | {s['median']:.3f} | {s['p95']:.3f} | {s['n']} "
                     f"| {p_text} | {ratio} |")
    m = report.get("machine", {})
    lines.append("")
    lines.append(f"This machine: {m.get('cpu', '?')}, {m.get('cores', '?')} cores. Paper: Intel i7-12700H, 16 GB.")
    return "\n".join(lines)


def write_json(path: str | os.PathLike, data: Mapping[str, Any]) -> None:
    write_json_atomic(path, data, indent=2, default=lambda o: o.item() if hasattr(o, "item") else str(o))
