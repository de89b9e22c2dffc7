"""The paper's evaluation protocol: episodes, sweeps, aggregation and tables.

This module holds the logic behind ``eval/table.py`` (Tables I and II),
``eval/latency.py`` (Table III) and ``eval/figures.py`` (Fig. 5); the scripts
only parse arguments.

Protocol (paper section V)
--------------------------
* A **strategy** chooses gamma every control step: the adaptive policy
  (``load_policy``), a fixed gamma, or a Stable-Baselines3 PPO policy.
* An **episode** is one reset of ``SOfAR-<Track>-v0`` at pace ratio ``rho``,
  run until a collision or leaving the track (failure) or the horizon
  (``duration``, 200 s in the paper; success).
* **Paired seeds**: episode ``e`` of ``(track, rho)`` is reset with
  :func:`episode_seed` ``(base_seed, track, rho, e)``, which does not depend on
  the strategy nor on the MIQP setting, so every strategy starts from the same
  randomised ego state and opponent field.
* Per (track, strategy) the table reports the success rate [%], the cumulative
  simulated time [s], the laps and overtakes summed over the episodes, plus
  collisions, track-limit violations, barrier-slack activity (% of control
  steps in which the MPC used DCBF slack), the step-weighted mean gamma and the
  controller failure counts.

Sweeps run episodes over a process pool (spawn context). Each worker pulls
tasks from a queue, builds its environments and policies lazily and keeps them
for later episodes of the same track/configuration. Results are appended to a
CSV one row per finished episode (flushed), and episodes already present in the
CSV are skipped, so an interrupted sweep resumes where it stopped.
"""

from __future__ import annotations

import csv
import hashlib
import importlib.metadata
import json
import logging
import math
import multiprocessing as mp
import os
import platform
import queue
import sys
import time
import traceback
import warnings
import zlib
from collections.abc import Callable, Iterable, Mapping, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from sofar_env.constants import CIRCUIT_ABBREVIATIONS, EPISODE_SECONDS, TABLE_ORDER
from sofar_env.constants import FIXED_GAMMAS as _FIXED_GAMMAS
from sofar_env.constants import RHOS as _RHOS

logger = logging.getLogger(__name__)

__all__ = [
    "TRACKS",
    "TRACK_ABBREVIATIONS",
    "RHOS",
    "FIXED_GAMMAS",
    "EPISODE_COLUMNS",
    "TRACE_COLUMNS",
    "PAPER_TABLE1_SUCCESS",
    "PAPER_LATENCY_MS",
    "Strategy",
    "EpisodeTask",
    "EpisodeResult",
    "Summary",
    "SweepStats",
    "episode_seed",
    "resolve_policy_path",
    "build_strategies",
    "table1_tasks",
    "miqp_ablation_tasks",
    "run_episode",
    "run_sweep",
    "run_table1",
    "run_miqp_ablation",
    "TableReport",
    "read_episode_csv",
    "select_rows",
    "paper_comparison",
    "summarize",
    "aggregate",
    "rank_marks",
    "format_table1",
    "format_table2",
    "latency_stats",
    "measure_latency",
    "format_latency",
    "machine_info",
    "read_trace_csv",
    "plot_gamma_figures",
]

TRACKS: tuple[str, ...] = TABLE_ORDER
"""The four circuits of the paper, in the paper's table order."""
TRACK_ABBREVIATIONS = CIRCUIT_ABBREVIATIONS
RHOS: tuple[float, ...] = _RHOS
"""Opponent pace ratios of the paper."""
FIXED_GAMMAS: tuple[float, ...] = _FIXED_GAMMAS
"""Fixed barrier decays of the paper's baselines."""
DEFAULT_DURATION = EPISODE_SECONDS
"""Episode horizon of the paper [s]."""

PAPER_TABLE1_SUCCESS = {
    "Indianapolis": {"adaptive": 72.0, 0.05: 28.0, 0.15: 44.0, 0.30: 56.0, 0.50: 44.0, 0.70: 68.0, 0.95: 16.0},
    "Kentucky": {"adaptive": 48.0, 0.05: 12.0, 0.15: 40.0, 0.30: 44.0, 0.50: 56.0, 0.70: 24.0, 0.95: 16.0},
    "LagunaSeca": {"adaptive": 76.0, 0.05: 0.0, 0.15: 68.0, 0.30: 64.0, 0.50: 48.0, 0.70: 56.0, 0.95: 12.0},
    "Monza": {"adaptive": 72.0, 0.05: 0.0, 0.15: 60.0, 0.30: 68.0, 0.50: 84.0, 0.70: 80.0, 0.95: 0.0},
}
"""Success rates [%] of the paper's Table I (for side-by-side reporting)."""
PAPER_LATENCY_MS = {"mpc_ms": (1.60, 0.34), "miqp_ms": (5.49, 1.73), "rl_ms": (0.82, 0.12)}
"""Paper Table III, mean and std [ms] on an Intel i7-12700H."""

EPISODE_COLUMNS: tuple[str, ...] = (
    "track", "strategy", "rho", "seed", "success", "sim_time", "laps", "overtakes", "collision", "off_track",
    "slack_steps", "steps", "mean_gamma", "mpc_failures", "miqp_failures", "wall_time",
    "episode", "use_miqp", "duration", "policy_id", "stack", "n_opponents",
)
"""Columns of the per-episode CSV (one row per episode)."""
TRACE_COLUMNS: tuple[str, ...] = (
    "track", "strategy", "rho", "seed", "step", "sim_time", "gamma", "nearest_opponent_m", "min_barrier",
)
"""Columns of the per-step trace CSV."""
_SLACK_TOL = 1e-4
"""DCBF slack above this counts as barrier-slack activity [units of h]."""


# --------------------------------------------------------------------------- strategies and tasks
@dataclass(frozen=True)
class Strategy:
    """How gamma is chosen: ``kind`` is ``"fixed"`` (``gamma``), ``"policy"`` or ``"sb3"`` (``path``)."""

    name: str
    """Label in the CSV, e.g. ``adaptive``, ``gamma=0.05``, ``sb3``."""
    kind: str
    gamma: float | None = None
    path: str | None = None
    policy_id: str = ""
    """Short content hash of the policy file ("" for fixed gammas); part of the resume key."""

    def __post_init__(self) -> None:
        if self.kind not in ("fixed", "policy", "sb3"):
            raise ValueError(f"unknown strategy kind {self.kind!r}")
        if self.kind == "fixed" and (self.gamma is None or not (0.0 < self.gamma <= 1.0)):
            raise ValueError(f"a fixed strategy needs gamma in (0, 1], got {self.gamma!r}")
        if self.kind != "fixed" and not self.path:
            raise ValueError(f"a {self.kind} strategy needs a path")

    @classmethod
    def fixed(cls, gamma: float) -> Strategy:
        return cls(name=f"gamma={gamma:.2f}", kind="fixed", gamma=float(gamma))

    @classmethod
    def adaptive(cls, path: str | os.PathLike, name: str = "adaptive") -> Strategy:
        """A PASTA checkpoint (``stem``, ``stem.json`` or ``stem.pt``); its id hashes the JSON and the weights."""
        from sofar_agents.policies import read_checkpoint_metadata

        _, json_path, pt_path = read_checkpoint_metadata(path)
        return cls(name=name, kind="policy", path=str(json_path), policy_id=_file_id(json_path, pt_path))

    @classmethod
    def sb3(cls, path: str | os.PathLike, name: str = "sb3") -> Strategy:
        return cls(name=name, kind="sb3", path=str(path), policy_id=_file_id(path))

    @property
    def label(self) -> str:
        """Display name in the Markdown tables."""
        if self.kind == "fixed":
            return f"γ = {self.gamma:.2f}"
        if self.kind == "sb3":
            return "PPO (SB3)"
        return "Adaptive" if self.name == "adaptive" else self.name

    def build(self) -> Callable[[Any], np.ndarray]:
        """The callable obs -> gamma array of shape (1,)."""
        if self.kind == "fixed":
            from sofar_agents import FixedGammaPolicy

            return FixedGammaPolicy(self.gamma)
        _limit_torch_threads()
        if self.kind == "sb3":
            from sofar_agents.policies import SB3Policy

            return SB3Policy(self.path)
        from sofar_agents import load_policy

        return load_policy(self.path)


def _file_id(*paths: str | os.PathLike) -> str:
    """First 10 hex digits of the SHA-1 of the files' contents."""
    h = hashlib.sha1()
    for path in paths:
        with open(path, "rb") as f:
            for chunk in iter(lambda: f.read(1 << 20), b""):
                h.update(chunk)
    return h.hexdigest()[:10]


def _limit_torch_threads() -> None:
    """One intra-op thread: the networks are tiny and the workers already use every core."""
    try:
        import torch

        torch.set_num_threads(1)
    except Exception:  # pragma: no cover - torch is a dependency, but timing code must not fail on it
        pass


def _fmt_float(x: float) -> str:
    return f"{float(x):g}"


@dataclass(frozen=True)
class EpisodeTask:
    """One episode to run."""

    track: str
    strategy: Strategy
    rho: float
    episode: int
    seed: int
    use_miqp: bool = True
    duration: float = DEFAULT_DURATION
    """Episode horizon [s]; reaching it without a collision or leaving the track is a success."""
    n_opponents: int | None = None
    """Opponent count (None: the environment's default, 4)."""
    stack: str = "sofar"
    """Controller preset (``"sofar"`` or ``"paper"``, see :func:`sofar_env.stack.stack_preset`)."""
    trace: bool = False
    """Record a per-step trace (gamma, nearest opponent, smallest barrier value)."""

    @property
    def key(self) -> tuple:
        return _key(self.track, self.strategy.name, self.strategy.policy_id, self.rho, self.seed, self.use_miqp,
                    self.duration, self.stack, self.n_opponents)

    @property
    def env_key(self) -> tuple:
        return (self.track, bool(self.use_miqp), float(self.duration), self.stack)


def _key(track, strategy, policy_id, rho, seed, use_miqp, duration, stack, n_opponents) -> tuple:
    """The resume key: every setting that changes an episode (rows of older files: stack "sofar", the
    default opponent count)."""
    n_opp = "" if n_opponents in (None, "") else str(int(float(n_opponents)))
    return (str(track), str(strategy), str(policy_id or ""), _fmt_float(rho), int(seed), bool(use_miqp),
            _fmt_float(duration), str(stack or "sofar"), n_opp)


def _row_key(row: Mapping[str, Any]) -> tuple:
    return _key(row["track"], row["strategy"], row.get("policy_id", ""), row["rho"], row["seed"],
                _as_bool(row.get("use_miqp", True)), row.get("duration", DEFAULT_DURATION),
                row.get("stack") or "sofar", row.get("n_opponents"))


def episode_seed(base_seed: int, track: str, rho: float, episode: int) -> int:
    """The reset seed of episode ``episode`` of ``(track, rho)``: the same for every strategy.

    Derived with :class:`numpy.random.SeedSequence` from the base seed, a CRC32 of the
    track name, rho in micro-units and the episode index: deterministic across
    processes, platforms and Python hash randomisation.
    """
    entropy = [int(base_seed) & 0xFFFFFFFF, zlib.crc32(str(track).encode("utf-8")),
               int(round(float(rho) * 1_000_000)), int(episode)]
    return int(np.random.SeedSequence(entropy).generate_state(1, np.uint32)[0])


def resolve_policy_path(path: str | os.PathLike | None = None,
                        fallback: str = "the Adaptive row is skipped") -> Path | None:
    """``path`` if given (must exist), else the shipped policy if it exists, else None.

    A missing shipped policy gives a warning that ends with ``fallback`` (what happens instead).
    """
    if path is not None:
        p = Path(path)
        if not p.exists() and not p.with_name(p.name + ".json").exists():
            raise FileNotFoundError(f"policy file not found: {p}")
        return p
    try:
        from sofar_agents import default_policy_path

        p = default_policy_path()
    except Exception as exc:  # missing checkpoint may raise
        warnings.warn(f"no shipped adaptive policy: {exc}. So {fallback}.", stacklevel=2)
        return None
    if p is None or not Path(p).exists():
        warnings.warn(f"the shipped adaptive policy {p} is missing (train one with train/pasta.py or pass "
                      f"--policy PATH). So {fallback}.", stacklevel=2)
        return None
    return Path(p)


def build_strategies(gammas: Sequence[float] = FIXED_GAMMAS, policy: str | os.PathLike | None = None,
                     sb3: str | os.PathLike | None = None, adaptive: bool = True) -> list[Strategy]:
    """Adaptive (``policy`` or the shipped one, when present), the fixed gammas, then SB3 PPO if given."""
    out: list[Strategy] = []
    if adaptive:
        p = resolve_policy_path(policy)
        if p is not None:
            out.append(Strategy.adaptive(p))
    out.extend(Strategy.fixed(g) for g in gammas)
    if sb3 is not None:
        if not Path(sb3).exists():
            raise FileNotFoundError(f"SB3 policy file not found: {sb3}")
        out.append(Strategy.sb3(sb3))
    names = [s.name for s in out]
    if len(set(names)) != len(names):
        raise ValueError(f"duplicate strategies: {names}")
    return out


def table1_tasks(strategies: Sequence[Strategy], tracks: Sequence[str] = TRACKS, rhos: Sequence[float] = RHOS,
                 episodes: int = 5, base_seed: int = 0, duration: float = DEFAULT_DURATION,
                 trace: bool | Callable[[Strategy], bool] = False, stack: str = "sofar") -> list[EpisodeTask]:
    """Every (track, rho, episode, strategy) of Table I, grouped by track so workers reuse environments."""
    tasks = []
    for track in tracks:
        for rho in rhos:
            for e in range(episodes):
                seed = episode_seed(base_seed, track, rho, e)
                for strat in strategies:
                    tr = trace(strat) if callable(trace) else bool(trace)
                    tasks.append(EpisodeTask(track, strat, float(rho), e, seed, True, float(duration), stack=stack,
                                             trace=tr))
    return tasks


def miqp_ablation_tasks(strategies: Sequence[Strategy], episodes: int = 10, rhos: Sequence[float] = RHOS,
                        track: str = "LagunaSeca", base_seed: int = 0,
                        duration: float = DEFAULT_DURATION, stack: str = "sofar") -> list[EpisodeTask]:
    """Table II: ``episodes`` episodes per (MIQP setting, strategy), rho cycling over ``rhos``.

    Episode ``k`` runs at ``rhos[k % len(rhos)]`` with the seed of episode ``k // len(rhos)``
    of that rho, so it pairs with Table I's episodes and across both settings.
    """
    tasks = []
    for use_miqp in (False, True):
        for k in range(episodes):
            rho = float(rhos[k % len(rhos)])
            e = k // len(rhos)
            seed = episode_seed(base_seed, track, rho, e)
            for strat in strategies:
                tasks.append(EpisodeTask(track, strat, rho, e, seed, use_miqp, float(duration), stack=stack))
    return tasks


# --------------------------------------------------------------------------- one episode
@dataclass
class EpisodeResult:
    """What one episode produced (one CSV row)."""

    track: str
    strategy: str
    rho: float
    seed: int
    success: bool
    sim_time: float
    laps: float
    overtakes: int
    collision: bool
    off_track: bool
    slack_steps: int
    steps: int
    mean_gamma: float
    mpc_failures: int
    miqp_failures: int
    wall_time: float
    episode: int = 0
    use_miqp: bool = True
    duration: float = DEFAULT_DURATION
    policy_id: str = ""
    stack: str = "sofar"
    n_opponents: int | str = ""
    """Opponent count of the episode ("" for the environment's default)."""

    def to_row(self) -> dict[str, Any]:
        row = asdict(self)
        return {k: row[k] for k in EPISODE_COLUMNS}


def _info_scalar(info: Mapping[str, Any], key: str, default: float = 0.0) -> float:
    v = info.get(key, default)
    try:
        v = float(np.asarray(v, dtype=float).reshape(-1)[0]) if np.ndim(v) else float(v)
    except (TypeError, ValueError, IndexError):
        return float(default)
    return v


def slack_active(info: Mapping[str, Any]) -> bool:
    """Whether the MPC used DCBF slack in this step, from the step's ``info``.

    Uses ``info["barrier_slack"]`` when the environment reports it; otherwise the safety
    cost (barrier slack + 1 per collision + 1 per leaving the track) minus the events.
    """
    if "barrier_slack" in info:
        return _info_scalar(info, "barrier_slack") > _SLACK_TOL
    if "cost" in info:
        events = float(bool(info.get("collision", False))) + float(bool(info.get("off_track", False)))
        return _info_scalar(info, "cost") - events > _SLACK_TOL
    return False


def run_episode(env, policy: Callable[[Any], Any], task: EpisodeTask) -> tuple[EpisodeResult, list[tuple]]:
    """Run one episode of ``task`` in ``env`` (already built for its track/MIQP setting).

    Returns the result and, when ``task.trace``, the per-step rows of :data:`TRACE_COLUMNS`.
    The episode ends at a termination (collision, leaving the track), at the environment's
    truncation, or once the simulated time reaches ``task.duration``.
    """
    options: dict[str, Any] = {"rho": float(task.rho)}
    if task.n_opponents is not None:
        options["n_opponents"] = int(task.n_opponents)
    t0 = time.perf_counter()
    obs, info = env.reset(seed=int(task.seed), options=options)
    steps = slack = 0
    gamma_sum = 0.0
    collision = off_track = terminated = truncated = False
    trace: list[tuple] = []
    while True:
        action = np.asarray(policy(obs), dtype=np.float32).reshape(1)
        obs, _, terminated, truncated, info = env.step(action)
        steps += 1
        gamma = _info_scalar(info, "gamma", float(action[0]))
        gamma_sum += gamma
        slack += int(slack_active(info))
        collision |= bool(info.get("collision", False))
        off_track |= bool(info.get("off_track", False))
        sim_time = _info_scalar(info, "sim_time", math.nan)
        if task.trace:
            trace.append((task.track, task.strategy.name, _fmt_float(task.rho), task.seed, steps, sim_time, gamma,
                          _info_scalar(info, "nearest_opponent_m", math.nan),
                          _info_scalar(info, "min_barrier", math.nan)))
        if terminated or truncated or sim_time >= task.duration - 1e-6:
            break
    if "is_success" in info and (terminated or truncated):
        success = bool(info["is_success"])
    else:  # stopped at our own horizon
        success = not (terminated or collision or off_track)
    if success and sim_time < task.duration - 1e-6:
        warnings.warn(f"the environment ended the episode at {sim_time:.1f} s, before the {task.duration:g} s "
                      "horizon", stacklevel=2)
    result = EpisodeResult(
        track=task.track, strategy=task.strategy.name, rho=float(task.rho), seed=int(task.seed), success=success,
        sim_time=float(sim_time), laps=_info_scalar(info, "laps"), overtakes=int(_info_scalar(info, "overtakes")),
        collision=collision, off_track=off_track, slack_steps=slack, steps=steps,
        mean_gamma=gamma_sum / max(steps, 1), mpc_failures=int(_info_scalar(info, "mpc_failures")),
        miqp_failures=int(_info_scalar(info, "miqp_failures")), wall_time=time.perf_counter() - t0,
        episode=int(task.episode), use_miqp=bool(task.use_miqp), duration=float(task.duration),
        policy_id=task.strategy.policy_id, stack=task.stack,
        n_opponents="" if task.n_opponents is None else int(task.n_opponents),
    )
    return result, trace


def make_env(track: str, use_miqp: bool = True, duration: float = DEFAULT_DURATION, stack: str = "sofar",
             **kwargs):
    """``gymnasium.make("SOfAR-<track>-v0")`` with the MIQP setting, the controller preset and the horizon."""
    import gymnasium as gym

    import sofar_env  # noqa: F401  (registers the environments)

    from sofar_env.race import RaceConfig

    # the registered ids cap episodes at 2000 steps (200 s); follow the requested horizon instead
    steps = int(math.ceil(float(duration) / RaceConfig().dt - 1e-9)) + 1
    return gym.make(f"SOfAR-{track}-v0", max_episode_steps=steps, use_miqp=bool(use_miqp),
                    config={"race": {"duration": float(duration)}, "stack": stack}, **kwargs)


class _EpisodeRunner:
    """Runs tasks, building environments and policies on first use and keeping them."""

    def __init__(self) -> None:
        self.envs: dict[tuple, Any] = {}
        self.policies: dict[Strategy, Callable] = {}

    def run(self, task: EpisodeTask) -> tuple[EpisodeResult, list[tuple]]:
        env = self.envs.get(task.env_key)
        if env is None:
            env = self.envs[task.env_key] = make_env(task.track, task.use_miqp, task.duration, task.stack)
        policy = self.policies.get(task.strategy)
        if policy is None:
            policy = self.policies[task.strategy] = task.strategy.build()
        return run_episode(env, policy, task)

    def close(self) -> None:
        for env in self.envs.values():
            try:
                env.close()
            except Exception:  # pragma: no cover
                pass
        self.envs.clear()


def _worker_loop(tasks, results) -> int:
    """Process-pool worker: run tasks from ``tasks`` until a None, report to ``results``."""
    warnings.simplefilter("ignore", UserWarning)  # the parent reports failures; keep worker output quiet
    runner = _EpisodeRunner()
    done = 0
    try:
        while True:
            item = tasks.get()
            if item is None:
                break
            idx, task = item
            try:
                result, trace = runner.run(task)
                results.put(("ok", idx, result.to_row(), trace))
            except Exception:
                results.put(("error", idx, traceback.format_exc(), None))
            done += 1
    finally:
        runner.close()
    return done


# --------------------------------------------------------------------------- CSV I/O
def _as_bool(x: Any) -> bool:
    if isinstance(x, str):
        return x.strip().lower() in ("1", "true", "yes", "1.0")
    return bool(x)


_INT_COLUMNS = {"seed", "overtakes", "slack_steps", "steps", "mpc_failures", "miqp_failures", "episode"}
_BOOL_COLUMNS = {"success", "collision", "off_track", "use_miqp"}
_FLOAT_COLUMNS = {"rho", "sim_time", "laps", "mean_gamma", "wall_time", "duration"}


def _parse_row(row: Mapping[str, Any]) -> dict[str, Any]:
    out = dict(row)
    for k, v in row.items():
        if k in _BOOL_COLUMNS:
            out[k] = _as_bool(v)
        elif k in _INT_COLUMNS:
            out[k] = int(float(v))
        elif k in _FLOAT_COLUMNS:
            out[k] = float(v)
    return out


def _csv_value(v: Any) -> Any:
    if isinstance(v, bool):
        return int(v)
    if isinstance(v, float):
        return f"{v:.6g}" if abs(v) < 1e5 else f"{v:.1f}"
    return v


def read_episode_csv(path: str | os.PathLike) -> list[dict[str, Any]]:
    """The rows of a per-episode CSV, typed; incomplete rows (a run killed mid-write) are dropped."""
    p = Path(path)
    if not p.exists() or p.stat().st_size == 0:
        return []
    rows = []
    with open(p, newline="") as f:
        reader = csv.DictReader(f)
        missing = [c for c in EPISODE_COLUMNS if c not in (reader.fieldnames or []) and c not in _ADDED_COLUMNS]
        if missing:
            raise ValueError(f"{p} is not a SOfAR episode CSV (missing columns {missing}); use another --out")
        for row in reader:
            if any(row.get(c) in (None, "") for c in EPISODE_COLUMNS if c not in _MAY_BE_EMPTY):
                continue
            try:
                rows.append(_parse_row(row))
            except ValueError:
                logger.warning("skipping an unreadable row of %s: %s", p, row)
    return rows


_ADDED_COLUMNS = {"stack": "sofar", "n_opponents": ""}
"""Columns added after the first format, with the value that rows of older files stand for."""
_MAY_BE_EMPTY = {"policy_id", "n_opponents"}


def _is_older_header(header: Sequence[str], columns: Sequence[str]) -> bool:
    return list(header) == [c for c in columns if c not in _ADDED_COLUMNS or c in header]


def _migrate_csv(path: Path, header: Sequence[str], columns: Sequence[str]) -> None:
    """Rewrite an episode CSV of an older format with the current columns (atomically)."""
    with open(path, newline="") as f:
        rows = [r for r in csv.DictReader(f)]
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(columns))
        w.writeheader()
        for r in rows:
            if None in r or any(v is None for v in r.values()):
                continue  # a torn last line
            w.writerow({c: r.get(c, _ADDED_COLUMNS.get(c, "")) for c in columns})
    os.replace(tmp, path)
    logger.info("%s: added the columns %s (older format)", path, [c for c in columns if c not in header])


class _AppendingCSV:
    """A CSV opened for appending: header when new, one flushed row per write."""

    def __init__(self, path: str | os.PathLike, columns: Sequence[str]) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        new = not self.path.exists() or self.path.stat().st_size == 0
        if not new:
            with open(self.path, "rb") as f:  # a run killed mid-line leaves no newline: start a fresh line
                f.seek(-1, os.SEEK_END)
                needs_newline = f.read(1) not in (b"\n", b"\r")
            with open(self.path, newline="") as f:
                header = next(csv.reader(f), [])
            if list(header) != list(columns) and _is_older_header(header, columns):
                _migrate_csv(self.path, header, columns)
                needs_newline = False
            elif list(header) != list(columns):
                raise ValueError(f"{self.path} has columns {header}, expected {list(columns)}; use another --out")
        self._f = open(self.path, "a", newline="")
        if not new and needs_newline:
            self._f.write("\n")
        self._w = csv.writer(self._f)
        self.columns = tuple(columns)
        if new:
            self._w.writerow(self.columns)
            self._f.flush()

    def write(self, row: Mapping[str, Any] | Sequence[Any]) -> None:
        values = [row[c] for c in self.columns] if isinstance(row, Mapping) else list(row)
        self._w.writerow([_csv_value(v) for v in values])
        self._f.flush()

    def write_many(self, rows: Iterable[Sequence[Any]]) -> None:
        self._w.writerows([[_csv_value(v) for v in r] for r in rows])
        self._f.flush()

    def close(self) -> None:
        self._f.close()


# --------------------------------------------------------------------------- sweeps
@dataclass
class SweepStats:
    """What a sweep did."""

    requested: int = 0
    skipped: int = 0
    """Episodes already in the CSV."""
    completed: int = 0
    failed: int = 0
    steps: int = 0
    """Control steps simulated by the completed episodes."""
    episode_wall_time: float = 0.0
    """Sum of the episodes' wall times [s] (about workers x elapsed)."""
    elapsed: float = 0.0
    """Wall time of the sweep [s]."""
    workers: int = 0
    errors: list[str] = field(default_factory=list)

    @property
    def steps_per_second_per_worker(self) -> float:
        return self.steps / self.episode_wall_time if self.episode_wall_time > 0 else math.nan

    def estimate_hours(self, total_steps: float, workers: int) -> float:
        """Wall hours for ``total_steps`` control steps on ``workers`` workers at the measured speed."""
        rate = self.steps_per_second_per_worker
        return total_steps / (rate * max(workers, 1)) / 3600.0 if rate > 0 else math.nan


def _progress_bar(total: int, enabled: bool):
    from tqdm.auto import tqdm

    return tqdm(total=total, unit="ep", desc="episodes", disable=not enabled, dynamic_ncols=True, smoothing=0.05)


def run_sweep(tasks: Sequence[EpisodeTask], csv_path: str | os.PathLike, *, workers: int | None = None,
              trace_path: str | os.PathLike | None = None, progress: bool = True) -> SweepStats:
    """Run every task not yet in ``csv_path``, appending one row per finished episode.

    ``workers`` processes (default ``os.cpu_count()``; 1 runs in this process). A failed episode
    is logged and left out of the CSV, so the next run retries it.
    """
    t_start = time.perf_counter()
    done = {_row_key(r) for r in read_episode_csv(csv_path)}
    pending, seen = [], set()
    for t in tasks:
        if t.key not in done and t.key not in seen:
            pending.append(t)
            seen.add(t.key)
    stats = SweepStats(requested=len(tasks), skipped=len(tasks) - len(pending))
    if not pending:
        stats.elapsed = time.perf_counter() - t_start
        return stats
    pending.sort(key=lambda t: (t.env_key, t.strategy.name))
    n_workers = max(1, min(int(workers or os.cpu_count() or 1), len(pending)))
    stats.workers = n_workers
    out = _AppendingCSV(csv_path, EPISODE_COLUMNS)
    trace_out = _AppendingCSV(trace_path, TRACE_COLUMNS) if trace_path is not None else None
    bar = _progress_bar(len(pending), progress)

    def handle(msg) -> None:
        status, idx, payload, trace = msg
        if status == "ok":
            out.write(payload)
            if trace_out is not None and trace:
                trace_out.write_many(trace)
            stats.completed += 1
            stats.steps += int(payload["steps"])
            stats.episode_wall_time += float(payload["wall_time"])
            rate = stats.steps / stats.episode_wall_time if stats.episode_wall_time > 0 else 0.0
            bar.set_postfix(steps_per_s=f"{rate * n_workers:.0f}", failed=stats.failed, refresh=False)
        else:
            stats.failed += 1
            stats.errors.append(payload)
            t = pending[idx]
            logger.error("episode %s/%s rho=%g seed=%d failed:\n%s", t.track, t.strategy.name, t.rho, t.seed, payload)
        bar.update(1)

    try:
        if n_workers == 1:
            runner = _EpisodeRunner()
            try:
                for i, t in enumerate(pending):
                    try:
                        res, trace = runner.run(t)
                        handle(("ok", i, res.to_row(), trace))
                    except Exception:
                        handle(("error", i, traceback.format_exc(), None))
            finally:
                runner.close()
        else:
            _run_pool(pending, n_workers, handle)
    finally:
        bar.close()
        out.close()
        if trace_out is not None:
            trace_out.close()
        stats.elapsed = time.perf_counter() - t_start
    return stats


def _run_pool(pending: Sequence[EpisodeTask], n_workers: int, handle: Callable) -> None:
    ctx = mp.get_context("spawn")
    with ctx.Manager() as manager:
        task_q, result_q = manager.Queue(), manager.Queue()
        for i, t in enumerate(pending):
            task_q.put((i, t))
        for _ in range(n_workers):
            task_q.put(None)
        received = 0
        pool = ProcessPoolExecutor(max_workers=n_workers, mp_context=ctx)
        try:
            futures = [pool.submit(_worker_loop, task_q, result_q) for _ in range(n_workers)]
            while received < len(pending):
                try:
                    msg = result_q.get(timeout=0.5)
                except queue.Empty:
                    if all(f.done() for f in futures):
                        break
                    continue
                handle(msg)
                received += 1
            while received < len(pending):  # drain what finished workers left behind
                try:
                    handle(result_q.get_nowait())
                    received += 1
                except queue.Empty:
                    break
            for f in futures:
                exc = f.exception() if f.done() else None
                if exc is not None:
                    logger.error("a worker process failed: %r", exc)
            if received < len(pending):
                logger.error("%d episodes got no result (a worker died); rerun to retry them",
                             len(pending) - received)
        except BaseException:
            pool.shutdown(wait=False, cancel_futures=True)
            raise
        pool.shutdown(wait=True)


# --------------------------------------------------------------------------- aggregation
@dataclass(frozen=True)
class Summary:
    """Totals over a group of episodes (one table cell row)."""

    episodes: int
    successes: int
    success_rate: float
    """[%]"""
    sim_time: float
    """Cumulative simulated time [s]."""
    laps: float
    overtakes: int
    collisions: int
    off_tracks: int
    slack_pct: float
    """Percentage of control steps with DCBF slack [%]."""
    mean_gamma: float
    """Step-weighted mean gamma."""
    mpc_failures: int
    miqp_failures: int
    steps: int
    wall_time: float


def summarize(rows: Iterable[Mapping[str, Any]]) -> Summary:
    """Totals of a list of episode rows (typed dicts or raw CSV strings)."""
    rows = [_parse_row(r) for r in rows]
    n = len(rows)
    steps = sum(r["steps"] for r in rows)
    return Summary(
        episodes=n,
        successes=sum(bool(r["success"]) for r in rows),
        success_rate=100.0 * sum(bool(r["success"]) for r in rows) / n if n else math.nan,
        sim_time=float(sum(r["sim_time"] for r in rows)),
        laps=float(sum(r["laps"] for r in rows)),
        overtakes=int(sum(r["overtakes"] for r in rows)),
        collisions=int(sum(bool(r["collision"]) for r in rows)),
        off_tracks=int(sum(bool(r["off_track"]) for r in rows)),
        slack_pct=100.0 * sum(r["slack_steps"] for r in rows) / steps if steps else math.nan,
        mean_gamma=sum(r["mean_gamma"] * r["steps"] for r in rows) / steps if steps else math.nan,
        mpc_failures=int(sum(r["mpc_failures"] for r in rows)),
        miqp_failures=int(sum(r["miqp_failures"] for r in rows)),
        steps=int(steps),
        wall_time=float(sum(r["wall_time"] for r in rows)),
    )


def aggregate(rows: Iterable[Mapping[str, Any]], by: Sequence[str] = ("track", "strategy")) -> dict[tuple, Summary]:
    """:func:`summarize` per group of the columns ``by``, groups in order of first appearance."""
    groups: dict[tuple, list] = {}
    for r in rows:
        r = _parse_row(r)
        groups.setdefault(tuple(r[c] for c in by), []).append(r)
    return {k: summarize(v) for k, v in groups.items()}


def rank_marks(values: Sequence[float], higher_is_better: bool = True, decimals: int | None = None) -> list[str]:
    """``"best"``, ``"second"`` or ``""`` for each value.

    Standard competition ranking on the values as displayed (rounded to ``decimals``):
    every value equal to the best is ``"best"``; when the best is unique, every value
    equal to the next distinct one is ``"second"`` (a tie for the best leaves no second
    place, as in 1-1-3 ranking). NaN is never marked.
    """
    vals = [float(v) for v in values]
    shown = [round(v, decimals) if decimals is not None and math.isfinite(v) else v for v in vals]
    distinct = sorted({v for v in shown if math.isfinite(v)}, reverse=higher_is_better)
    best = distinct[0] if distinct else None
    second = distinct[1] if len(distinct) > 1 and shown.count(best) == 1 else None
    return ["best" if v == best else "second" if v == second else "" for v in shown]


@dataclass(frozen=True)
class _Column:
    header: str
    attr: str
    decimals: int
    rank: bool = False


_TABLE1_COLUMNS = (
    _Column("Success [%] ↑", "success_rate", 1, True),
    _Column("Sim time [s] ↑", "sim_time", 1, True),
    _Column("Laps ↑", "laps", 2, True),
    _Column("Overtakes ↑", "overtakes", 0, True),
    _Column("Collisions", "collisions", 0),
    _Column("Off-track", "off_tracks", 0),
    _Column("Slack [% steps]", "slack_pct", 1),
    _Column("Mean γ", "mean_gamma", 2),
    _Column("MPC fail.", "mpc_failures", 0),
    _Column("Episodes", "episodes", 0),
)
_TABLE2_COLUMNS = (
    _Column("Succ. [%] ↑", "success_rate", 1, True),
    _Column("Time [s] ↑", "sim_time", 1, True),
    _Column("Laps ↑", "laps", 2, True),
    _Column("Overt. ↑", "overtakes", 0, True),
    _Column("Collisions", "collisions", 0),
    _Column("Off-track", "off_tracks", 0),
    _Column("Slack [% steps]", "slack_pct", 1),
    _Column("Episodes", "episodes", 0),
)


def _cell(value: float, decimals: int, mark: str) -> str:
    text = "–" if not math.isfinite(float(value)) else f"{float(value):.{decimals}f}"
    return f"**{text}**" if mark == "best" else f"<u>{text}</u>" if mark == "second" else text


def _markdown_blocks(first_header: str, blocks: Sequence[tuple[str, Sequence[tuple[str, Summary]]]],
                     columns: Sequence[_Column], rank_within_block: bool = True) -> str:
    head = [first_header, "Strategy", *[c.header for c in columns]]
    lines = ["| " + " | ".join(head) + " |", "|" + "|".join(["---", "---"] + ["---:"] * len(columns)) + "|"]
    all_rows = [(b, lab, s) for b, rows in blocks for lab, s in rows]

    def marks_for(items):
        return {c.attr: rank_marks([getattr(s, c.attr) for _, _, s in items], True, c.decimals) if c.rank
                else [""] * len(items) for c in columns}

    if rank_within_block:
        marks = {}
        for b, rows in blocks:
            items = [(b, lab, s) for lab, s in rows]
            m = marks_for(items)
            for i, it in enumerate(items):
                marks[id(it[2]), b, it[1]] = {a: m[a][i] for a in m}
    else:
        m = marks_for(all_rows)
        marks = {(id(s), b, lab): {a: m[a][i] for a in m} for i, (b, lab, s) in enumerate(all_rows)}
    for b, rows in blocks:
        for j, (lab, s) in enumerate(rows):
            mk = marks[id(s), b, lab]
            cells = [b if j == 0 else "", lab] + [_cell(getattr(s, c.attr), c.decimals, mk[c.attr]) for c in columns]
            lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def format_table1(rows: Iterable[Mapping[str, Any]], strategies: Sequence[Strategy] | None = None,
                  tracks: Sequence[str] | None = None, aggregate_row: bool = True) -> str:
    """Table I as Markdown: per track, one row per strategy; best **bold**, second <u>underlined</u>.

    Ranking is within each track (and within the aggregate block over all tracks) for success
    rate, simulated time, laps and overtakes (higher is better).
    """
    rows = [_parse_row(r) for r in rows]
    if tracks is None:
        tracks = [t for t in TRACKS if any(r["track"] == t for r in rows)]
        tracks += sorted({r["track"] for r in rows} - set(tracks))
    if strategies is None:
        names = list(dict.fromkeys(r["strategy"] for r in rows))
        labels = {n: n for n in names}
    else:
        names = [s.name for s in strategies]
        labels = {s.name: s.label for s in strategies}
    per = aggregate(rows, ("track", "strategy"))
    blocks = []
    for t in tracks:
        items = [(labels[n], per[(t, n)]) for n in names if (t, n) in per]
        if items:
            abbr = TRACK_ABBREVIATIONS.get(t, t)
            blocks.append((t if abbr == t else f"{t} ({abbr})", items))
    if aggregate_row and len(blocks) > 1:
        tot = aggregate([r for r in rows if r["track"] in tracks], ("strategy",))
        blocks.append(("All circuits", [(labels[n], tot[(n,)]) for n in names if (n,) in tot]))
    return _markdown_blocks("Track", blocks, _TABLE1_COLUMNS)


def format_table2(rows: Iterable[Mapping[str, Any]], strategies: Sequence[Strategy] | None = None) -> str:
    """Table II as Markdown: with and without the MIQP layer; ranking over all four rows as in the paper."""
    rows = [_parse_row(r) for r in rows]
    names = [s.name for s in strategies] if strategies else list(dict.fromkeys(r["strategy"] for r in rows))
    labels = {s.name: s.label for s in strategies} if strategies else {n: n for n in names}
    per = aggregate(rows, ("use_miqp", "strategy"))
    blocks = []
    for use, title in ((False, "w/o MIQP"), (True, "w/ MIQP")):
        items = [(labels[n], per[(use, n)]) for n in names if (use, n) in per]
        if items:
            blocks.append((title, items))
    return _markdown_blocks("Setting", blocks, _TABLE2_COLUMNS, rank_within_block=False)


def select_rows(rows: Iterable[Mapping[str, Any]], tasks: Sequence[EpisodeTask]) -> list[dict[str, Any]]:
    """The rows of ``rows`` that belong to ``tasks`` (a CSV may hold episodes of other runs)."""
    wanted = {t.key for t in tasks}
    out, seen = [], set()
    for r in rows:
        k = _row_key(r)
        if k in wanted and k not in seen:
            out.append(_parse_row(r))
            seen.add(k)
    return out


def paper_comparison(rows: Iterable[Mapping[str, Any]], strategies: Sequence[Strategy]) -> str:
    """Markdown: our success rate next to the paper's (Table I) for the strategies the paper has."""
    per = aggregate(rows, ("track", "strategy"))
    lines = ["| Track | Strategy | Success [%] (this run) | Success [%] (paper) |", "|---|---|---:|---:|"]
    for t in TRACKS:
        for s in strategies:
            key = "adaptive" if s.kind == "policy" else round(s.gamma, 2) if s.kind == "fixed" else None
            paper = PAPER_TABLE1_SUCCESS.get(t, {}).get(key)
            if (t, s.name) in per and paper is not None:
                lines.append(f"| {t} | {s.label} | {per[(t, s.name)].success_rate:.1f} | {paper:.1f} |")
    return "\n".join(lines) if len(lines) > 2 else ""


# --------------------------------------------------------------------------- whole runs
FULL_TABLE1_STEPS = len(TRACKS) * len(RHOS) * 5 * (1 + len(FIXED_GAMMAS)) * int(DEFAULT_DURATION / 0.1)
"""Control steps of a full Table I if every episode lasted 200 s (700 episodes x 2000 = 1.4 M)."""


@dataclass
class TableReport:
    """Outcome of :func:`run_table1` / :func:`run_miqp_ablation`."""

    markdown: str
    stats: SweepStats
    csv_path: Path
    markdown_path: Path
    rows: list[dict[str, Any]]


def _run_header(title: str, settings: Mapping[str, Any]) -> str:
    items = ", ".join(f"{k} = {v}" for k, v in settings.items())
    return f"# {title}\n\n{items}. Generated {time.strftime('%Y-%m-%d %H:%M')}.\n"


def _stats_text(stats: SweepStats) -> str:
    if stats.completed == 0:
        return f"{stats.skipped} episodes taken from the CSV, none run."
    rate = stats.steps_per_second_per_worker
    return (f"{stats.completed} episodes run ({stats.skipped} taken from the CSV, {stats.failed} failed) "
            f"with {stats.workers} workers in {stats.elapsed:.0f} s: {stats.steps} control steps, "
            f"{rate:.0f} steps/s per worker.")


def run_table1(strategies: Sequence[Strategy], out_dir: str | os.PathLike = "results", *,
               tracks: Sequence[str] = TRACKS, rhos: Sequence[float] = RHOS, episodes: int = 5, base_seed: int = 0,
               duration: float = DEFAULT_DURATION, workers: int | None = None, trace: bool = False,
               progress: bool = True, prefix: str = "table1", stack: str = "sofar") -> TableReport:
    """Table I: run (or resume) the sweep into ``out_dir/<prefix>_episodes.csv``, write ``<prefix>.md``.

    With ``trace``, the per-step trace of the non-fixed strategies goes to ``<prefix>_trace.csv``.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    tasks = table1_tasks(strategies, tracks, rhos, episodes, base_seed, duration,
                         trace=(lambda s: s.kind != "fixed") if trace else False, stack=stack)
    csv_path = out / f"{prefix}_episodes.csv"
    stats = run_sweep(tasks, csv_path, workers=workers, progress=progress,
                      trace_path=out / f"{prefix}_trace.csv" if trace else None)
    rows = select_rows(read_episode_csv(csv_path), tasks)
    settings = {"tracks": ", ".join(tracks), "rho": ", ".join(_fmt_float(r) for r in rhos),
                "episodes per (track, rho)": episodes, "horizon": f"{duration:g} s", "base seed": base_seed,
                "controller": stack}
    parts = [_run_header("Table I: performance per circuit", settings),
             "Per circuit and metric, **bold** is the best and <u>underlined</u> the second best "
             "(success rate, simulated time, laps, overtakes: higher is better). Slack: percentage of control "
             "steps in which the MPC used DCBF slack.\n",
             format_table1(rows, strategies, tracks)]
    cmp = paper_comparison(rows, strategies)
    if cmp:
        parts += ["\n## Success rate next to the paper's Table I\n", cmp]
    missing = len(tasks) - len(rows)
    if missing:
        parts.append(f"\n**Incomplete:** {missing} of {len(tasks)} episodes are missing; rerun the same command "
                     "to finish them.")
    parts.append("\n" + _stats_text(stats))
    md = "\n".join(parts) + "\n"
    md_path = out / f"{prefix}.md"
    md_path.write_text(md)
    return TableReport(md, stats, csv_path, md_path, rows)


def run_miqp_ablation(strategies: Sequence[Strategy], out_dir: str | os.PathLike = "results", *,
                      episodes: int = 10, rhos: Sequence[float] = RHOS, track: str = "LagunaSeca",
                      base_seed: int = 0, duration: float = DEFAULT_DURATION, workers: int | None = None,
                      progress: bool = True, prefix: str = "table2", stack: str = "sofar") -> TableReport:
    """Table II: ``track`` with and without the MIQP layer, into ``out_dir/<prefix>_episodes.csv`` and ``.md``."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    tasks = miqp_ablation_tasks(strategies, episodes, rhos, track, base_seed, duration, stack=stack)
    csv_path = out / f"{prefix}_episodes.csv"
    stats = run_sweep(tasks, csv_path, workers=workers, progress=progress)
    rows = select_rows(read_episode_csv(csv_path), tasks)
    settings = {"track": track, "rho cycled over": ", ".join(_fmt_float(r) for r in rhos),
                "episodes per (setting, strategy)": episodes, "horizon": f"{duration:g} s", "base seed": base_seed,
                "controller": stack}
    parts = [_run_header("Table II: with and without the MIQP layer", settings),
             "**Bold** is the best and <u>underlined</u> the second best over the four rows (as in the paper).\n",
             format_table2(rows, strategies)]
    missing = len(tasks) - len(rows)
    if missing:
        parts.append(f"\n**Incomplete:** {missing} of {len(tasks)} episodes are missing; rerun the same command "
                     "to finish them.")
    parts.append("\n" + _stats_text(stats))
    md = "\n".join(parts) + "\n"
    md_path = out / f"{prefix}.md"
    md_path.write_text(md)
    return TableReport(md, stats, csv_path, md_path, rows)


# --------------------------------------------------------------------------- latency (Table III)
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
    env = make_env(track, True, max(float(seconds), 1.0) + 10.0, decision_interval=1)
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


# --------------------------------------------------------------------------- figures (Fig. 5)
def read_trace_csv(path: str | os.PathLike, strategy: str | None = None) -> dict[str, np.ndarray]:
    """gamma and nearest-opponent distance from a trace CSV (optionally one strategy only)."""
    gam, dist, barrier = [], [], []
    with open(path, newline="") as f:
        for row in csv.DictReader(f):
            if strategy is not None and row.get("strategy") != strategy:
                continue
            try:
                gam.append(float(row["gamma"]))
                dist.append(float(row["nearest_opponent_m"]))
                barrier.append(float(row.get("min_barrier", "nan") or "nan"))
            except (KeyError, ValueError):
                continue
    return {"gamma": np.asarray(gam), "nearest_opponent_m": np.asarray(dist), "min_barrier": np.asarray(barrier)}


def plot_gamma_figures(trace: Mapping[str, np.ndarray], out_dir: str | os.PathLike, max_distance: float = 100.0,
                       title: str = "") -> list[Path]:
    """Fig. 5: the gamma histogram and nearest-opponent distance vs gamma, as PNGs in ``out_dir``.

    Distances beyond ``max_distance`` (or non-finite: no opponent in view) are left out of the
    scatter; the binned mean +- std of gamma per distance bin is drawn over it.
    """
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    g = np.asarray(trace["gamma"], float)
    d = np.asarray(trace["nearest_opponent_m"], float)
    paths = []

    fig, ax = plt.subplots(figsize=(4.0, 3.0), dpi=150)
    ax.hist(g[np.isfinite(g)], bins=np.linspace(0.0, 1.0, 41), color="tab:blue", edgecolor="white", linewidth=0.4)
    ax.set_xlabel(r"$\gamma$")
    ax.set_ylabel("control steps")
    ax.set_xlim(0.0, 1.0)
    ax.set_title(title or r"$\gamma$ distribution", fontsize=9)
    fig.tight_layout()
    paths.append(out / "gamma_hist.png")
    fig.savefig(paths[-1])
    plt.close(fig)

    ok = np.isfinite(g) & np.isfinite(d) & (d <= max_distance)
    fig, ax = plt.subplots(figsize=(4.0, 3.0), dpi=150)
    ax.scatter(d[ok], g[ok], s=3, alpha=0.25, color="tab:blue", linewidths=0, label="steps")
    if ok.sum() >= 10:
        edges = np.linspace(0.0, max_distance, 21)
        centres, means, stds = [], [], []
        for lo, hi in zip(edges[:-1], edges[1:]):
            sel = ok & (d >= lo) & (d < hi)
            if sel.sum() >= 5:
                centres.append(0.5 * (lo + hi))
                means.append(g[sel].mean())
                stds.append(g[sel].std())
        if centres:
            ax.errorbar(centres, means, yerr=stds, color="tab:red", lw=1.2, capsize=2, label="bin mean ± std")
            ax.legend(fontsize=7, loc="lower right")
    ax.set_xlabel("distance to nearest opponent [m]")
    ax.set_ylabel(r"$\gamma$")
    ax.set_ylim(0.0, 1.05)
    ax.set_title(title or r"distance vs. $\gamma$", fontsize=9)
    fig.tight_layout()
    paths.append(out / "distance_vs_gamma.png")
    fig.savefig(paths[-1])
    plt.close(fig)
    return paths


def write_json(path: str | os.PathLike, data: Mapping[str, Any]) -> None:
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    p.write_text(json.dumps(data, indent=2, default=lambda o: o.item() if hasattr(o, "item") else str(o)) + "\n")
