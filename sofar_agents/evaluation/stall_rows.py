"""Stalled episodes as rows and tasks: the CSV side of :mod:`sofar_agents.evaluation.stalls`.

The stalled fixed-gamma episodes of a table as tasks to replay (:func:`stalled_tasks`), a fresh paired seed
set (:func:`fresh_tasks`), one report row per episode (:func:`report_rows`), the step records of a stall as
rows (:func:`record_rows`) and read back (:func:`records_from_rows`).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import asdict, fields

from sofar_agents.evaluation.interventions import _outcome
from sofar_agents.evaluation.protocol import EpisodeTask, Strategy, ended_tasks, table1_tasks
from sofar_agents.evaluation.stalls import StallReport, StepRecord, rooms

__all__ = ["stalled_tasks", "fresh_tasks", "report_rows", "record_rows", "records_from_rows", "REPORT_COLUMNS",
           "RECORD_COLUMNS"]


def stalled_tasks(rows: Iterable[Mapping], stacks: Sequence[str] | None = None) -> list[EpisodeTask]:
    """The stalled fixed-gamma episodes of per-episode CSV rows (typed, :func:`read_episode_csv`) as tasks."""
    return ended_tasks(rows, "stalled", stacks)


def fresh_tasks(stacks: Sequence[str], gammas: Sequence[float], tracks: Sequence[str], rhos: Sequence[float],
                episodes: int, base_seed: int, n_opponents: int = 8, scenario: str = "interactive",
                duration: float = 200.0) -> list[EpisodeTask]:
    """Table I's episodes of every (stack, gamma) on a base seed (paired: the same seeds for every stack)."""
    strategies = [Strategy.fixed(g) for g in gammas]
    per_stack = [table1_tasks(strategies, tracks, rhos, episodes, base_seed, duration, stack=stack, scenario=scenario,
                              n_opponents=n_opponents) for stack in stacks]
    # interleaved by episode (each episode's presets and gammas together), so that a partial run stays paired
    return [t for group in zip(*per_stack) for t in group]


REPORT_COLUMNS = ("label", "track", "rho", "seed", "stack", "config_hash", "gamma", "outcome", "sim_time", "cls",
                  "decision", "fallback", "follow", "stopped_ahead", "angled", "away", "e", "v_plan", "v_ref",
                  "gap_ahead", "v_ahead", "room_beside", "corner_room", "turn_room", "row_room", "v_next", "accel", "n",
                  "n_ref", "track_slack", "barrier_slack", "h_min", "plan_slack", "followed_v", "onset_t",
                  "onset_decision", "onset_e", "onset_gap", "onset_v_ahead", "restarts", "wall_time")
"""Columns of :func:`report_rows` (one row per episode; ``config_hash``: that of the episode's resolved configuration,
as its row in a per-episode CSV carries it; ``restarts``: times the controller's restart mode came on, empty in rows
of a preset with a restart mode recorded before it was counted)."""


def report_rows(reports: Iterable[StallReport]) -> list[dict]:
    """One row of :data:`REPORT_COLUMNS` per episode (evidence fields empty when it did not stall)."""
    rows = []
    for rep in reports:
        t, r = rep.task, rep.result
        row = {"label": rep.label, "track": t.track, "rho": t.rho, "seed": t.seed, "stack": t.stack,
               "config_hash": t.config_hash, "gamma": t.strategy.gamma, "outcome": _outcome(r),
               "sim_time": round(r.sim_time, 1), "cls": rep.cls,
               "restarts": rep.restarts, "wall_time": round(r.wall_time, 2)}
        for c in REPORT_COLUMNS:
            row.setdefault(c, rep.evidence.get(c, ""))
        rows.append(row)
    return rows


def record_rows(report: StallReport) -> list[dict]:
    """The step records of a stalled episode as CSV rows (with the episode's identity)."""
    t = report.task
    head = {"track": t.track, "rho": t.rho, "seed": t.seed, "stack": t.stack, "gamma": t.strategy.gamma}
    return [{**head, **{k: (round(v, 4) if isinstance(v, float) else v) for k, v in asdict(r).items()}}
            for r in report.records]


def records_from_rows(rows: Iterable[Mapping]) -> dict[tuple, list[StepRecord]]:
    """The step records of a ``records.csv`` by episode ``(track, rho, seed, stack, gamma)`` (strings as written),
    with ``turn_room`` and ``row_room`` computed again by :func:`rooms` (files of an earlier version of the
    recorder measured them otherwise)."""
    from sofar_env.stack.config import stack_preset
    from sofar_env.stack.edges import TrackEdges
    from sofar_env.tracks import Track
    from sofar_env.vehicle import AV21

    names = [f.name for f in fields(StepRecord)]
    kinds = {f.name: f.type for f in fields(StepRecord)}
    edges: dict[str, TrackEdges] = {}
    out: dict[tuple, list[StepRecord]] = {}
    for r in rows:
        key = (r["track"], r["rho"], r["seed"], r["stack"], r["gamma"])
        values = {}
        for name in names:
            raw = r.get(name, "")
            kind = kinds[name]
            values[name] = (int(float(raw)) if kind == "int" else str(raw) if kind == "str"
                            else float(raw) if raw not in ("", None) else math.nan)
        if r["track"] not in edges:
            edges[r["track"]] = TrackEdges(Track.load(r["track"]), AV21)
        preset = stack_preset(r["stack"].split("+")[0])  # "<stack>+restart<w>": a probe of eval/stalls.py
        values.update(rooms(edges[r["track"]], AV21, preset.mpc, values["s"], values["n"],
                            values["e"]))
        out.setdefault(key, []).append(StepRecord(**values))
    return out


RECORD_COLUMNS = ("track", "rho", "seed", "stack", "gamma") + tuple(f.name for f in fields(StepRecord))
"""Columns of :func:`record_rows`."""
