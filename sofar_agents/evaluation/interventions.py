"""Could a gamma chosen *during* a race have saved it? Counterfactual switches before each failure.

:mod:`~sofar_agents.evaluation.headroom` bounds what a gamma chosen once per episode or per
condition could gain. This module measures the within-race part, which only a per-step policy
can reach. For each failed episode of a fixed gamma it

1. replays the episode (same circuit, pace ratio, seed and settings) and finds the control step at
   which it failed (on this machine: a seeded run is reproducible on one instruction set, so an
   episode recorded elsewhere may now end otherwise; it is then reported as not reproduced);
2. runs it again with gamma switched to another value in a window before that step, and back to
   the base gamma ``hold_s`` after it (:class:`Intervention`);
3. records whether the switch **rescued** the episode (it reached the horizon without a collision,
   leaving the track or stalling) and whether it at least got past the moment of the base failure
   (**delayed**: it succeeded, or failed more than ``hold_s`` after that step).

A rescue alone does not show that the other gamma was what the moment needed. A race's outcome
turns on small perturbations (:func:`~sofar_agents.evaluation.headroom.outcome_flips`): any change of
the trajectory re-draws it. :func:`default_interventions` therefore adds two placebo controls with
the same window length:

- **tiny change**: the window's gamma is only ``placebo_delta`` (0.01) above the base gamma, a
  perturbation that barely changes the barrier;
- **displaced**: the strongest switch, ``placebo_lead_s`` (20 s) earlier, at a moment unrelated to
  the failure.

Rescues beyond the placebos' are what a state-dependent gamma could gain, *if* a policy could tell
the moments apart; rescues at the placebos' rate are re-drawn outcomes that no policy can aim at.

The replays run on the executor (:mod:`sofar_agents.executor`), one task per failed episode
(:class:`ReplayTask`: its base replay and every intervention), with the resume and fault behaviour of Table I:
:func:`replay_interventions` appends each episode's rows to ``interventions.csv`` as it finishes, skips the
episodes whose rows the file already holds (by the episode's resume key, which holds the configuration hash of
the ``config_hash`` column, and the interventions asked for), counts the episodes that failed or were lost with a
worker, and once every episode is in the file rewrites it with the run's rows in task order (the file a run
without interruptions writes).
"""

from __future__ import annotations

import csv
import math
import os
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from sofar_agents.evaluation.episode import make_env, run_episode
from sofar_agents.evaluation.paired import PairedComparison, format_paired, paired_comparison
from sofar_agents.evaluation.protocol import EpisodeTask, Strategy, _key, exact_text, gamma_text
from sofar_agents.evaluation.results import LEGACY_STACK, read_csv_rows
from sofar_agents.executor import Job, RunStats, execute

__all__ = ["Intervention", "InterventionResult", "INTERVENTION_COLUMNS", "ReplayTask", "default_interventions",
           "failed_episodes", "intervene", "run_interventions", "replay_interventions", "summarize_interventions",
           "placebo_comparisons", "format_interventions", "intervention_rows", "results_from_rows"]

_CONTROL_DT = 0.1
"""Seconds per env step of the registered environments: one decision per control step of
``sofar_env.race.RaceConfig().dt`` (a test keeps the two equal)."""

_GAMMA_MIN, _GAMMA_MAX = 0.05, 1.0


def _outcome(result) -> str:
    if result.success:
        return "success"
    if result.collision:
        return "collision"
    if result.off_track:
        return "off_track"
    return "stalled" if result.stalled else "failure"


@dataclass(frozen=True)
class Intervention:
    """Gamma ``gamma`` from ``window_s + lead_s`` seconds before the failure to ``hold_s - lead_s`` after it."""

    gamma: float
    """The gamma inside the window (action units, in [0.05, 1])."""
    window_s: float
    """How long before the failure step the window opens [s]."""
    hold_s: float = 2.0
    """How long after the failure step the window stays open [s] (the replay may fail later)."""
    lead_s: float = 0.0
    """Shift of the whole window to earlier times [s]; > 0 makes a displaced placebo."""
    kind: str = "switch"
    """``"switch"``, ``"tiny"`` (placebo: a tiny change) or ``"displaced"`` (placebo: an earlier window)."""

    def __post_init__(self) -> None:
        if not (_GAMMA_MIN <= self.gamma <= _GAMMA_MAX):
            raise ValueError(f"intervention gamma must lie in [{_GAMMA_MIN}, {_GAMMA_MAX}], got {self.gamma!r}")
        for name in ("window_s", "hold_s", "lead_s"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0.0):
                raise ValueError(f"intervention {name} must be a finite number >= 0 s, got {v!r}")
        if self.window_s + self.hold_s <= 0.0:
            raise ValueError("an intervention window needs window_s + hold_s > 0")
        if self.kind not in ("switch", "tiny", "displaced"):
            raise ValueError(f"intervention kind must be 'switch', 'tiny' or 'displaced', got {self.kind!r}")

    @property
    def label(self) -> str:
        """Its name in the reports and paired comparisons: holds the exact gamma and times, so two
        interventions share a label only if they are the same."""
        s = f"γ {gamma_text(self.gamma)}, {exact_text(self.window_s)} s before"
        if self.lead_s:
            s += f", {exact_text(self.lead_s)} s earlier"
        return s

    def steps(self, failure_step: int, dt: float = _CONTROL_DT) -> tuple[int, int]:
        """The window ``[first, end)`` in env steps (0-based indices of the actions) for a failure at
        step ``failure_step`` (the 1-based count of steps of the failed episode)."""
        lead = round(self.lead_s / dt)
        first = max(0, failure_step - round(self.window_s / dt) - lead)
        end = max(0, failure_step + round(self.hold_s / dt) - lead)
        return first, end


class _Schedule:
    """obs -> gamma: ``base`` outside ``[first, end)`` (counted in calls), ``gamma`` inside."""

    def __init__(self, base: float, gamma: float = math.nan, first: int = 0, end: int = 0) -> None:
        self.base, self.gamma, self.first, self.end = float(base), float(gamma), int(first), int(end)
        self.k = 0

    def __call__(self, obs) -> list[float]:
        g = self.gamma if self.first <= self.k < self.end else self.base
        self.k += 1
        return [g]


@dataclass(frozen=True)
class InterventionResult:
    """One replay of a failed episode (the base replay has ``intervention=None``)."""

    episode: EpisodeTask
    """The replayed episode (its strategy is the base gamma)."""
    base_gamma: float
    intervention: Intervention | None
    base_steps: int
    """Steps of the base replay on this machine (the failure step if it failed)."""
    base_outcome: str
    steps: int
    outcome: str
    """``success``, ``collision``, ``off_track`` or ``stalled``."""
    config_hash: str = ""
    """The configuration hash of the replayed environment ("": rows written before the column)."""

    @property
    def rescued(self) -> bool:
        return self.intervention is not None and self.base_outcome != "success" and self.outcome == "success"

    @property
    def delayed(self) -> bool:
        """The replay got past the base replay's failure: it succeeded, or failed more than the
        intervention's ``hold_s`` after the step at which the base replay failed."""
        if self.intervention is None or self.base_outcome == "success":
            return False
        return self.outcome == "success" or self.steps > self.base_steps + round(self.intervention.hold_s / _CONTROL_DT)


INTERVENTION_COLUMNS = ("track", "rho", "seed", "stack", "scenario", "use_miqp", "duration", "n_opponents",
                        "base_gamma", "kind", "gamma", "window_s", "hold_s", "lead_s", "base_steps", "base_outcome",
                        "steps", "outcome", "rescued", "delayed", "config_hash")
"""Columns of :func:`intervention_rows` (``kind`` is ``base`` for the base replay)."""
ADDED_COLUMNS = {"config_hash": ""}
"""Columns that files of an older layout lack, with the value their rows stand for (no hash: reused by no task)."""
_MAY_BE_EMPTY = ("n_opponents", "window_s", "hold_s", "lead_s", "config_hash")


def intervention_rows(results: Iterable[InterventionResult]) -> list[dict[str, Any]]:
    """One CSV row per replay (columns :data:`INTERVENTION_COLUMNS`)."""
    rows = []
    for r in results:
        e, iv = r.episode, r.intervention
        rows.append({
            "track": e.track, "rho": e.rho, "seed": e.seed, "stack": e.stack, "scenario": e.scenario,
            "use_miqp": int(e.use_miqp), "duration": e.duration,
            "n_opponents": "" if e.n_opponents is None else e.n_opponents, "base_gamma": r.base_gamma,
            "kind": "base" if iv is None else iv.kind, "gamma": r.base_gamma if iv is None else iv.gamma,
            "window_s": "" if iv is None else iv.window_s, "hold_s": "" if iv is None else iv.hold_s,
            "lead_s": "" if iv is None else iv.lead_s, "base_steps": r.base_steps, "base_outcome": r.base_outcome,
            "steps": r.steps, "outcome": r.outcome, "rescued": int(r.rescued), "delayed": int(r.delayed),
            "config_hash": r.config_hash})
    return rows


def results_from_rows(rows: Iterable[Mapping[str, Any]]) -> list[InterventionResult]:
    """The inverse of :func:`intervention_rows`: results from the rows of an ``interventions.csv``
    (values as strings or numbers), e.g. to re-make its report without running an episode."""
    out = []
    for k, r in enumerate(rows):
        try:
            n_opp = r.get("n_opponents", "")
            base = float(r["base_gamma"])
            task = EpisodeTask(track=str(r["track"]), strategy=Strategy.fixed(base), rho=float(r["rho"]), episode=0,
                               seed=int(r["seed"]), use_miqp=bool(int(r["use_miqp"])), duration=float(r["duration"]),
                               n_opponents=None if n_opp in ("", None) else int(float(n_opp)),
                               stack=str(r["stack"]), scenario=str(r["scenario"]))
            iv = None if r["kind"] == "base" else Intervention(
                float(r["gamma"]), float(r["window_s"]), float(r["hold_s"]), float(r["lead_s"]), str(r["kind"]))
            out.append(InterventionResult(task, base, iv, int(r["base_steps"]), str(r["base_outcome"]),
                                          int(r["steps"]), str(r["outcome"]), str(r.get("config_hash") or "")))
        except (KeyError, TypeError, ValueError) as exc:
            raise ValueError(f"row {k + 1} is not an interventions.csv row: {exc}") from exc
    return out


def default_interventions(base_gamma: float, gammas: Sequence[float] = (0.15, 0.3, 0.6),
                          windows_s: Sequence[float] = (1.0, 2.0, 4.0), hold_s: float = 2.0,
                          placebo_delta: float = 0.01, placebo_lead_s: float = 20.0) -> list[Intervention]:
    """Every (gamma, window) switch, then the two placebos at the longest window (see the module docstring)."""
    if not gammas or not windows_s:
        raise ValueError("need at least one intervention gamma and one window")
    out = [Intervention(float(g), float(w), hold_s) for w in windows_s for g in gammas]
    w = float(max(windows_s))
    out.append(Intervention(round(min(float(base_gamma) + placebo_delta, _GAMMA_MAX), 6), w, hold_s, kind="tiny"))
    out.append(Intervention(float(max(gammas, key=lambda g: abs(g - base_gamma))), w, hold_s, placebo_lead_s,
                            kind="displaced"))
    return out


def failed_episodes(rows: Iterable[Mapping[str, Any]], gamma: float, limit: int | None = None) -> list[EpisodeTask]:
    """The failed episodes of the fixed gamma ``gamma`` in per-episode CSV rows
    (:func:`~sofar_agents.evaluation.read_episode_csv`) as tasks of that gamma, in file order, at most ``limit``."""
    strategy = Strategy.fixed(gamma)
    out = []
    for r in rows:
        if r["strategy"] != strategy.name or r["success"]:
            continue
        n_opp = r.get("n_opponents", "")
        out.append(EpisodeTask(
            track=str(r["track"]), strategy=strategy, rho=float(r["rho"]), episode=int(r.get("episode", 0)),
            seed=int(r["seed"]), use_miqp=bool(r["use_miqp"]), duration=float(r["duration"]),
            n_opponents=None if n_opp in ("", None) else int(float(n_opp)), stack=str(r.get("stack") or LEGACY_STACK),
            scenario=str(r.get("scenario") or "paper")))
        if limit is not None and len(out) >= limit:
            break
    return out


def _replay(env, task: EpisodeTask, schedule: _Schedule) -> tuple[int, str, str]:
    result, _ = run_episode(env, schedule, task)
    return result.steps, _outcome(result), result.config_hash


def intervene(task: EpisodeTask, interventions: Sequence[Intervention]) -> list[InterventionResult]:
    """Replay ``task`` (a fixed-gamma episode), then once per intervention; the base replay comes first.
    If the base replay does not fail on this machine, only it is returned."""
    if task.strategy.kind != "fixed":
        raise ValueError(f"interventions replay a fixed-gamma episode, got strategy {task.strategy.name!r}")
    base_gamma = float(task.strategy.gamma)
    env = make_env(task.track, use_miqp=task.use_miqp, duration=task.duration, stack=task.stack,
                   scenario=task.scenario)
    try:
        k_fail, base_out, env_hash = _replay(env, task, _Schedule(base_gamma))
        out = [InterventionResult(task, base_gamma, None, k_fail, base_out, k_fail, base_out, env_hash)]
        if base_out == "success":
            return out
        for iv in interventions:
            first, end = iv.steps(k_fail)
            if end <= first:  # a displaced window that would lie before the start
                continue
            steps, outcome, _ = _replay(env, task, _Schedule(base_gamma, iv.gamma, first, end))
            out.append(InterventionResult(task, base_gamma, iv, k_fail, base_out, steps, outcome, env_hash))
        return out
    finally:
        env.close()


@dataclass(frozen=True)
class ReplayTask:
    """One failed episode to replay: its base replay, then once per intervention (:func:`intervene`)."""

    episode: EpisodeTask
    interventions: tuple[Intervention, ...]

    @property
    def key(self) -> tuple:
        """The episode's resume key (configuration hash included); the interventions are the run's, checked
        against the rows by :class:`InterventionJob`."""
        return self.episode.key


class InterventionRunner:
    """The executor's worker body for replays: :func:`intervene` (it builds and closes the episode's env)."""

    def run(self, task: ReplayTask) -> list[InterventionResult]:
        return intervene(task.episode, task.interventions)

    def close(self) -> None:
        pass


def _row_episode_key(row: Mapping[str, Any]) -> tuple:
    """The resume key of the episode an ``interventions.csv`` row replayed (that of its :class:`ReplayTask`)."""
    return _key(row["track"], Strategy.fixed(float(row["base_gamma"])).name, "", row["rho"], int(row["seed"]),
                bool(int(row["use_miqp"])), row["duration"], row["stack"], row["n_opponents"], row["scenario"],
                row.get("config_hash") or "")


def _row_intervention(row: Mapping[str, Any]) -> Intervention | None:
    if row["kind"] == "base":
        return None
    return Intervention(float(row["gamma"]), float(row["window_s"]), float(row["hold_s"]), float(row["lead_s"]),
                        str(row["kind"]))


def _episode_rows(rows: Iterable[Mapping[str, Any]], interventions: Sequence[Intervention]) -> dict[tuple, list]:
    """Per episode key, the rows of a complete replay of the episode with ``interventions``, in the order a
    replay writes them (base, then the interventions in their order; of rows given twice, the last): the base row,
    and a row for every intervention whose window is not empty (none after a base replay that did not fail)."""
    groups: dict[tuple, dict] = {}
    for r in rows:
        groups.setdefault(_row_episode_key(r), {})[_row_intervention(r)] = r
    out = {}
    for key, by_iv in groups.items():
        base = by_iv.get(None)
        if base is None:
            continue
        wanted = [] if base["base_outcome"] == "success" else [
            iv for iv in interventions if iv.steps(int(base["base_steps"]))[1] > iv.steps(int(base["base_steps"]))[0]]
        if all(iv in by_iv for iv in wanted):
            out[key] = [base] + [by_iv[iv] for iv in wanted]
    return out


def _read_rows(path: Path) -> list[dict[str, str]]:
    return read_csv_rows(path, INTERVENTION_COLUMNS, added=ADDED_COLUMNS, may_be_empty=_MAY_BE_EMPTY,
                         kind="interventions CSV")


def _write_rows(path: Path, rows: Iterable[Mapping[str, Any]]) -> None:
    """Replace ``path`` (atomically) with ``rows`` under :data:`INTERVENTION_COLUMNS`."""
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=INTERVENTION_COLUMNS, lineterminator="\n")
        w.writeheader()
        w.writerows({c: r.get(c, ADDED_COLUMNS.get(c, "")) for c in INTERVENTION_COLUMNS} for r in rows)
    os.replace(tmp, path)


class InterventionJob(Job):
    """Replays as an executor job: each finished episode's rows are appended (flushed) to ``csv_path`` (if given)
    and its results kept in ``results`` under its key. Done: the episodes whose complete replay with
    ``interventions`` the file holds (:func:`_episode_rows`); a file of an older layout, or with a torn last line,
    is rewritten in the current layout (its complete rows) before the first append. ``runner``: a picklable
    factory of the worker body (None: :class:`InterventionRunner`)."""

    unit = "episodes"

    def __init__(self, csv_path: str | os.PathLike | None, interventions: Sequence[Intervention],
                 runner: Any = None) -> None:
        self.runner = runner or InterventionRunner
        self.csv_path = None if csv_path is None else Path(csv_path)
        self.interventions = tuple(interventions)
        self.results: dict[tuple, list[InterventionResult]] = {}
        self._f = self._w = None

    def done_keys(self) -> set:
        if self.csv_path is None:
            return set()
        return set(_episode_rows(_read_rows(self.csv_path), self.interventions))

    def open(self, pending) -> None:
        if self.csv_path is None:
            return
        self.csv_path.parent.mkdir(parents=True, exist_ok=True)
        if not self.csv_path.exists() or self.csv_path.stat().st_size == 0:
            _write_rows(self.csv_path, [])
        elif not self.csv_path.read_text().endswith("\n") or (
                self.csv_path.read_text().split("\n", 1)[0].split(",") != list(INTERVENTION_COLUMNS)):
            _write_rows(self.csv_path, _read_rows(self.csv_path))
        self._f = open(self.csv_path, "a", newline="")
        self._w = csv.DictWriter(self._f, fieldnames=INTERVENTION_COLUMNS, lineterminator="\n")

    def write(self, task: ReplayTask, payload: list[InterventionResult], stats: RunStats) -> None:
        if self._w is not None:
            self._w.writerows(intervention_rows(payload))
            self._f.flush()
        self.results[task.key] = payload

    def close(self) -> None:
        if self._f is not None:
            self._f.close()
            self._f = self._w = None

    def describe(self, task: ReplayTask) -> str:
        e = task.episode
        return f"replays of episode {e.track}/{e.strategy.name} rho={e.rho:g} seed={e.seed:d}"


def run_interventions(tasks: Sequence[EpisodeTask], interventions: Sequence[Intervention],
                      workers: int = 1) -> list[InterventionResult]:
    """:func:`intervene` for every task, on the executor with ``workers`` (>= 1) worker processes (1: in this
    process); results in the tasks' order, nothing written. ``RuntimeError`` (with the first traceback) if an
    episode failed or was lost with its worker."""
    if workers < 1:
        raise ValueError(f"workers must be >= 1, got {workers}")
    job = InterventionJob(None, interventions)
    replays = [ReplayTask(t, tuple(interventions)) for t in tasks]
    stats = execute(replays, job, workers=workers, progress=False)
    if stats.unfinished:
        raise RuntimeError(f"{stats.unfinished} of {len(tasks)} replays did not finish"
                           + (f":\n{stats.errors[0]}" if stats.errors else ""))
    return [r for t in replays for r in job.results[t.key]]


def replay_interventions(tasks: Sequence[EpisodeTask], interventions: Sequence[Intervention],
                         csv_path: str | os.PathLike, *, workers: int = 1,
                         progress: bool = False) -> tuple[list[InterventionResult], RunStats]:
    """Run (or resume) the replays of ``tasks`` into ``csv_path`` on the executor (module docstring).

    Returns the results of the tasks' complete replays in the file, in the tasks' order (read back from the rows:
    :func:`results_from_rows`), and the executor's stats: ``stats.unfinished`` episodes failed or were lost with a
    worker (logged; a rerun retries them). When every task's replays are in the file, it is rewritten with exactly
    those rows in task order (rows of other runs or configurations are dropped, as a new run replaces the file).
    ``workers`` < 1 raises ``ValueError`` before anything is read or run.
    """
    if workers < 1:
        raise ValueError(f"workers must be >= 1, got {workers}")
    replays = [ReplayTask(t, tuple(interventions)) for t in tasks]
    stats = execute(replays, InterventionJob(csv_path, interventions), workers=workers, progress=progress)
    path = Path(csv_path)
    done = _episode_rows(_read_rows(path), interventions) if path.exists() else {}
    keys = list(dict.fromkeys(t.key for t in replays))
    rows = [r for k in keys if k in done for r in done[k]]
    if keys and all(k in done for k in keys):
        _write_rows(path, rows)
    return results_from_rows(rows), stats


def summarize_interventions(results: Sequence[InterventionResult]) -> dict[str, Any]:
    """Counts: episodes replayed, failures reproduced, and per intervention the episodes it ran on,
    rescued and delayed (in the order of first appearance)."""
    base = [r for r in results if r.intervention is None]
    failed = [r for r in base if r.base_outcome != "success"]
    rows: dict[Intervention, dict[str, int]] = {}
    for r in results:
        if r.intervention is None:
            continue
        c = rows.setdefault(r.intervention, {"episodes": 0, "rescued": 0, "delayed": 0})
        c["episodes"] += 1
        c["rescued"] += int(r.rescued)
        c["delayed"] += int(r.delayed)
    outcomes: dict[str, int] = {}
    for r in failed:
        outcomes[r.base_outcome] = outcomes.get(r.base_outcome, 0) + 1
    return {"replayed": len(base), "failed": len(failed), "not_reproduced": len(base) - len(failed),
            "failure_kinds": outcomes, "interventions": rows}


def placebo_comparisons(results: Sequence[InterventionResult]) -> list[PairedComparison]:
    """Each switch of the displaced placebo's window against that placebo, on the failures both were run on:
    rescued counts as success, compared with :func:`~sofar_agents.evaluation.paired_comparison` (exact McNemar).
    A timely gamma is worth something only where the switch wins clearly more of the discordant failures."""
    rows = [{"track": r.episode.track, "rho": r.episode.rho, "seed": r.episode.seed, "use_miqp": r.episode.use_miqp,
             "strategy": r.intervention.label, "success": r.rescued}
            for r in results if r.intervention is not None and r.base_outcome != "success"]
    ivs = list(dict.fromkeys(r.intervention for r in results if r.intervention is not None))
    out = []
    for placebo in (iv for iv in ivs if iv.kind == "displaced"):
        for iv in ivs:
            if iv.kind == "switch" and (iv.window_s, iv.hold_s) == (placebo.window_s, placebo.hold_s):
                out.append(paired_comparison({"": rows}, iv.label, placebo.label))
    return out


def format_interventions(summary: Mapping[str, Any], base_gamma: float,
                         comparisons: Sequence[PairedComparison] = ()) -> str:
    """The summary as a Markdown table (share of the reproduced failures rescued / delayed), then the
    :func:`placebo_comparisons` if given."""
    kinds = ", ".join(f"{v} {k.replace('_', '-')}" for k, v in sorted(summary["failure_kinds"].items()))
    head = (f"Base gamma {gamma_text(base_gamma)}: {summary['replayed']} failed episodes replayed, {summary['failed']} "
            f"failed again on this machine ({kinds or 'none'}), {summary['not_reproduced']} did not.")
    lines = [head, "",
             "| intervention | kind | episodes | rescued | rescued [%] | got past the base failure |",
             "|---|---|---:|---:|---:|---:|"]
    for iv, c in summary["interventions"].items():
        pct = 100.0 * c["rescued"] / c["episodes"] if c["episodes"] else float("nan")
        kind = {"switch": "switch", "tiny": "placebo: tiny change", "displaced": "placebo: displaced"}[iv.kind]
        lines.append(f"| {iv.label} | {kind} | {c['episodes']} | {c['rescued']} | {pct:.0f} | {c['delayed']} |")
    text = "\n".join(lines) + "\n"
    if comparisons:
        text += ("\nTimely switches against the displaced placebo, on the failures both were run on (A: the switch, "
                 "B: the placebo; success = rescued):\n\n" + format_paired(comparisons))
    return text
