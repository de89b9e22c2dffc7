"""Where does a policy's gamma cost pace? Seeded replays of a policy with its gamma raised to a floor in chosen states.

A diagnostic intervention, not a controller: the policy runs as it is, except that in the states a
:class:`GammaFloor` names (every step, only with no opponent within a radius, or only with one within it) the gamma
the environment applies is ``max(policy's gamma, floor)``. Run on the same seeded episodes as the policy alone and as
fixed gammas, the rows say which of the policy's choices cost overtakes: if raising its gamma only where no car is
near recovers the pace, the cautious gamma it chooses there is what costs it, not the gamma it chooses beside a car.

The state test reads ``info["nearest_opponent_m"]`` of the previous ``reset``/``step`` (the distance the policy's
decision was made at). Rows are episode rows (:data:`~sofar_agents.evaluation.results.EPISODE_COLUMNS`) whose
strategy names carry the floor (``pasta w=<preference> floor 0.15 beyond 20 m``), so a results file resumes like any
sweep and ``eval/paired.py --pareto FILE --b NAME`` pairs every variant with any other.
"""

from __future__ import annotations

import dataclasses
import math
import os
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from sofar_agents.evaluation.episode import run_episode
from sofar_agents.evaluation.files import write_text_atomic
from sofar_agents.evaluation.protocol import DEFAULT_DURATION, RHOS, TRACKS, EpisodeTask, Strategy, table1_tasks
from sofar_agents.evaluation.results import read_episode_csv, select_rows
from sofar_agents.evaluation.runner import EpisodeRunner
from sofar_agents.evaluation.sweep import EpisodeJob, SweepStats
from sofar_agents.executor import execute
from sofar_env.constants import GAMMA_MAX, GAMMA_MIN

__all__ = ["FLOOR_GAMMAS", "WHERES", "FloorGamma", "FloorReport", "FloorRunner", "GammaFloor", "floor_strategies",
           "run_floor_study"]

WHERES: tuple[str, ...] = ("always", "far", "near")
"""Where a floor applies: every step, only when no opponent is within ``radius`` (``far``), only when one is
(``near``)."""

FLOOR_GAMMAS: tuple[float, ...] = (0.05, 0.15, 0.3, 0.5)
"""The fixed gammas a floor study runs beside the policy unless told otherwise (the script's and a manifest's)."""

GAMMA_RANGE: tuple[float, float] = (GAMMA_MIN, GAMMA_MAX)
"""The environments' gamma range: a floor outside it would be clipped away or do nothing."""


@dataclass(frozen=True)
class GammaFloor:
    """Raise the gamma to ``floor`` where ``where`` holds (:data:`WHERES`) for the nearest opponent's distance."""

    floor: float
    where: str = "always"
    radius: float = 20.0
    """Distance between reference points [m] that separates ``near`` from ``far``."""

    def __post_init__(self) -> None:
        lo, hi = GAMMA_RANGE
        if not (isinstance(self.floor, (int, float)) and math.isfinite(self.floor) and lo <= self.floor <= hi):
            raise ValueError(f"floor must be a gamma in [{lo:g}, {hi:g}], got {self.floor!r}")
        if self.where not in WHERES:
            raise ValueError(f"where must be one of {', '.join(WHERES)}, got {self.where!r}")
        if not (isinstance(self.radius, (int, float)) and math.isfinite(self.radius) and self.radius > 0):
            raise ValueError(f"radius must be a positive finite distance [m], got {self.radius!r}")

    def applies(self, nearest: float) -> bool:
        """Whether the floor holds with the nearest opponent ``nearest`` m away (``inf``/NaN: none, i.e. far)."""
        if self.where == "always":
            return True
        near = math.isfinite(nearest) and nearest < self.radius
        return near if self.where == "near" else not near

    @property
    def label(self) -> str:
        """The suffix of a floored strategy's name, e.g. ``floor 0.15 beyond 20 m``."""
        text = f"floor {self.floor:g}"
        if self.where == "far":
            return f"{text} beyond {self.radius:g} m"
        return f"{text} within {self.radius:g} m" if self.where == "near" else text


class FloorGamma(gym.Wrapper):
    """``env`` with its gamma raised per ``spec`` (a :class:`GammaFloor`). The wrapper holds no resource of its own:
    closing it closes ``env``, so do not close it when ``env`` is shared."""

    def __init__(self, env: Any, spec: GammaFloor) -> None:
        super().__init__(env)
        self.floor_spec = spec
        self._nearest = math.inf

    def _note(self, info: Mapping[str, Any]) -> None:
        self._nearest = float(info.get("nearest_opponent_m", math.inf))

    def reset(self, **kwargs):
        obs, info = self.env.reset(**kwargs)
        self._note(info)
        return obs, info

    def step(self, action):
        a = np.array(action, dtype=np.float32).reshape(-1)
        if self.floor_spec.applies(self._nearest):
            a[0] = max(float(a[0]), self.floor_spec.floor)
        obs, reward, terminated, truncated, info = self.env.step(a)
        self._note(info)
        return obs, reward, terminated, truncated, info


class FloorRunner(EpisodeRunner):
    """:class:`~sofar_agents.evaluation.runner.EpisodeRunner` whose strategies named in ``floors`` run with their
    gamma floored (:class:`FloorGamma` around the cached environment); every other strategy runs as in a sweep."""

    def __init__(self, floors: Mapping[str, GammaFloor]) -> None:
        super().__init__()
        self.floors = dict(floors)

    def run(self, task: EpisodeTask):
        env, policy = self.env_and_policy(task)
        spec = self.floors.get(task.strategy.name)
        return run_episode(env if spec is None else FloorGamma(env, spec), policy, task)


def floor_strategies(policy: str | os.PathLike, preference: Sequence[float], floors: Sequence[GammaFloor],
                     gammas: Sequence[float] = ()) -> tuple[list[Strategy], dict[str, GammaFloor]]:
    """The fixed ``gammas``, ``policy`` at ``preference`` as it is (named as in a Pareto sweep,
    ``pasta w=<weights>``) and once per floor (``pasta w=<weights> <floor label>``); and the floors by name."""
    base = "pasta w=" + "/".join(f"{w:.3g}" for w in preference)
    strategies = [Strategy.fixed(g) for g in gammas] + [Strategy.adaptive(policy, name=base, preference=preference)]
    named: dict[str, GammaFloor] = {}
    for spec in floors:
        name = f"{base} {spec.label}"
        if name in named:
            raise ValueError(f"two floors share the name {name!r}")
        named[name] = spec
        strategies.append(Strategy.adaptive(policy, name=name, preference=preference))
    return strategies, named


def _trace_columns(trace: Mapping[str, np.ndarray] | None, radius: float) -> str:
    """``| steps traced | mean gamma near | mean gamma far | at the range's floor |`` of one strategy's trace."""
    if trace is None or not len(trace["gamma"]):
        return " | | | |"
    g, d = trace["gamma"], trace["nearest_opponent_m"]
    near = np.isfinite(d) & (d < radius)

    def mean(mask: np.ndarray) -> str:
        return f"{g[mask].mean():.3f} ({100.0 * mask.mean():.0f} %)" if mask.any() else "-"

    at_floor = 100.0 * float(np.mean(g <= GAMMA_RANGE[0] + 1e-6))
    return f" {len(g):,} | {mean(near)} | {mean(~near)} | {at_floor:.0f} % |"


def _summary(rows: Sequence[Mapping[str, Any]], strategies: Sequence[Strategy], settings: Mapping[str, Any],
             trace_path: Path | None, radius: float) -> str:
    from sofar_agents.evaluation.results import read_trace_csv

    lines = ["# A policy's gamma floored in chosen states: success and pace on the same seeded episodes", ""]
    lines += [f"- {k}: {v}" for k, v in settings.items()]
    head = "| strategy | episodes | success [%] | overtakes per hour | mean gamma |"
    rule = "|---|---:|---:|---:|---:|"
    if trace_path is not None:
        head += (f" steps traced | mean gamma, a car within {radius:g} m (share of steps) | beyond {radius:g} m "
                 f"| steps at gamma {GAMMA_RANGE[0]:g} |")
        rule += "---:|---:|---:|---:|"
    lines += ["", head, rule]
    for strat in strategies:
        mine = [r for r in rows if r["strategy"] == strat.name]
        if not mine:
            continue
        hours = sum(float(r["sim_time"]) for r in mine) / 3600.0
        rate = sum(int(r["overtakes"]) for r in mine) / hours if hours > 0 else 0.0
        success = 100.0 * sum(bool(r["success"]) for r in mine) / len(mine)
        gamma = float(np.mean([float(r["mean_gamma"]) for r in mine]))
        line = f"| {strat.name} | {len(mine)} | {success:.1f} | {rate:.0f} | {gamma:.3f} |"
        if trace_path is not None:
            line += _trace_columns(read_trace_csv(trace_path, strat.name) if trace_path.exists() else None, radius)
        lines.append(line)
    lines += ["", "Mean gamma: the gamma the environment applied (after the floor), averaged per episode, then over "
              "the episodes. Paired tests of any two rows: `python eval/paired.py --pareto <episodes csv> --b NAME`."]
    if trace_path is not None:
        lines.append("Traced columns: over the control steps of the traced episodes (`floor_trace.csv`), split by the "
                     "nearest opponent's distance after the step.")
    return "\n".join(lines) + "\n"


@dataclass
class FloorReport:
    """What :func:`run_floor_study` did: the run's statistics (``stats.unfinished`` episodes failed or were lost: a
    rerun retries them), the Markdown summary and its path."""

    stats: SweepStats
    markdown: str
    path: Path


def run_floor_study(policy: str | os.PathLike, preference: Sequence[float], floors: Sequence[GammaFloor],
                    out_dir: str | os.PathLike, *, gammas: Sequence[float] = (), tracks: Sequence[str] = TRACKS,
                    rhos: Sequence[float] = RHOS, episodes: int = 2, base_seed: int = 0,
                    duration: float = DEFAULT_DURATION, workers: int | None = None, progress: bool = True,
                    stack: str = "sofar", scenario: str = "paper", n_opponents: int | None = None,
                    trace: bool = False, tasks_filter: Callable[[EpisodeTask], bool] | None = None
                    ) -> FloorReport | None:
    """Run (or resume) ``policy`` at ``preference``, floored by each of ``floors`` and as it is, and the fixed
    ``gammas``, on the seeded episodes of a Table I sweep (``tracks`` x ``rhos`` x ``episodes`` from
    ``base_seed``) into ``out_dir/floor_episodes.csv``; write ``out_dir/floor.md`` (one row per strategy).
    ``trace``: also record every control step (``out_dir/floor_trace.csv``) and report each strategy's gamma near
    and away from cars (the radius of the first floor, 20 m without one). ``tasks_filter`` (re-making committed
    rows): run only the episodes it keeps, write no summary and return None."""
    strategies, named = floor_strategies(policy, preference, floors, gammas)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    tasks = table1_tasks(strategies, tracks, rhos, episodes, base_seed, duration, stack=stack, scenario=scenario,
                         n_opponents=n_opponents)
    csv_path = out / "floor_episodes.csv"
    trace_path = out / "floor_trace.csv" if trace else None
    if trace:
        tasks = [dataclasses.replace(t, trace=True) for t in tasks]
    job = EpisodeJob(csv_path, trace_path, partial(FloorRunner, named))
    run = tasks if tasks_filter is None else [t for t in tasks if tasks_filter(t)]
    stats = execute(run, job, workers=workers, backend="local", progress=progress, stats=SweepStats())
    if tasks_filter is not None:
        return None
    rows = select_rows(read_episode_csv(csv_path), tasks)
    shown = Path(policy).resolve()
    shown = shown.relative_to(Path.cwd()) if shown.is_relative_to(Path.cwd()) else shown
    settings = {"policy": str(shown), "preference": "/".join(f"{w:.3g}" for w in preference),
                "controller": stack, "world": scenario, "opponents": "default" if n_opponents is None else n_opponents,
                "tracks": ", ".join(tracks), "rho": ", ".join(f"{r:g}" for r in rhos),
                "episodes per (track, rho)": episodes, "base seed": base_seed, "horizon": f"{duration:g} s"}
    md = _summary(rows, strategies, settings, trace_path, floors[0].radius if floors else 20.0)
    if len(rows) < len(tasks):
        md += f"\n**Incomplete:** {len(tasks) - len(rows)} of {len(tasks)} episodes are missing; rerun to finish.\n"
    path = out / "floor.md"
    write_text_atomic(path, md)
    return FloorReport(stats, md, path)
