"""A Pareto view of gamma strategies: success against overtaking, and the hypervolume of each front.

Every strategy of a sweep (a fixed gamma, or the preference-conditioned PASTA policy at one
preference) is one point

    (aggregate success rate [%], overtakes per hour of simulated racing [1/h])

over the same seeded episodes (the Table I protocol: :func:`~.protocol.table1_tasks`). Both
objectives are maximised. A **front** is the set of points of one family (the fixed gammas;
the policy's preferences) that no other point of the family dominates, and its
**hypervolume** is the area dominated by the front and bounded below by the reference point
``(0 %, 0 /h)`` (the worst value of each objective), in units of % x 1/h. It is computed
with pymoo's ``HV`` indicator (a minimiser: the points are negated); one family beats
another on this view when its hypervolume is larger.

The policy's preferences (:func:`preference_family`) move weight between the first two
objectives of the reward vector, safety and overtakes, and keep a fixed small weight on the
other three, so a sweep over them traces what one trained policy offers from cautious to
aggressive. ``eval/pareto.py`` is the command line.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from sofar_agents.evaluation.configs import episode_config, write_config_json
from sofar_agents.evaluation.files import write_json_atomic, write_text_atomic
from sofar_agents.evaluation.protocol import DEFAULT_DURATION, RHOS, TRACKS, Strategy, _fmt_float, table1_tasks
from sofar_agents.evaluation.results import pool_seed_sets, read_episode_csv, read_seed_sets, select_rows
from sofar_agents.evaluation.sweep import SweepStats, run_sweep

__all__ = ["OBJECTIVE_LABELS", "REFERENCE_POINT", "ParetoPoint", "ParetoReport", "preference_family",
           "strategy_points", "pareto_front", "hypervolume", "plot_fronts", "pareto_strategies", "run_pareto"]

OBJECTIVE_LABELS = ("success [%]", "overtakes per hour")
"""The two objectives of a point (both maximised)."""
REFERENCE_POINT = (0.0, 0.0)
"""Reference point of the hypervolume: the worst value of each objective."""
_OTHER_WEIGHT = 0.1
"""Weight kept on the other objectives (progress, barrier margin, gamma smoothness) by :func:`preference_family`."""


@dataclass(frozen=True)
class ParetoPoint:
    """One strategy on the Pareto view."""

    name: str
    family: str
    """``"fixed"`` (a fixed gamma) or ``"policy"`` (the policy at one preference)."""
    success: float
    """Aggregate success rate [%]."""
    overtakes_per_hour: float
    """Overtakes per hour of simulated racing [1/h]."""
    episodes: int
    preference: tuple[float, ...] | None = None


@dataclass
class ParetoReport:
    """Outcome of :func:`run_pareto`."""

    points: list[ParetoPoint]
    hypervolume: dict[str, float]
    """Hypervolume of each family's front [% x 1/h]."""
    markdown: str
    stats: SweepStats
    paths: dict[str, Path]


def preference_family(safety_weights: Sequence[float], n_objectives: int = 5,
                      other_weight: float = _OTHER_WEIGHT) -> list[tuple[float, ...]]:
    """Preferences ``(w_safety, 1 - other_weight - w_safety, other_weight / (n - 2), ...)``.

    Each ``w_safety`` must lie in ``[0, 1 - other_weight]``; the vectors sum to 1.
    """
    if n_objectives < 3:
        raise ValueError(f"n_objectives must be >= 3, got {n_objectives}")
    if not 0.0 <= other_weight < 1.0:
        raise ValueError(f"other_weight must lie in [0, 1), got {other_weight}")
    top = 1.0 - other_weight
    out = []
    for w in safety_weights:
        w = float(w)
        if not (math.isfinite(w) and 0.0 <= w <= top + 1e-12):
            raise ValueError(f"a safety weight must lie in [0, {top:g}], got {w!r}")
        rest = other_weight / (n_objectives - 2)
        out.append((round(w, 12), round(top - w, 12)) + (rest,) * (n_objectives - 2))
    return out


def strategy_points(rows: Sequence[Mapping[str, Any]], strategies: Sequence[Strategy]) -> list[ParetoPoint]:
    """The point of every strategy with at least one episode in ``rows`` (CSV rows of a sweep)."""
    points = []
    for strat in strategies:
        mine = [r for r in rows if r["strategy"] == strat.name]
        if mine:
            family = {"fixed": "fixed", "sb3": "baseline"}.get(strat.kind, "policy")
            points.append(_point(strat.name, family, mine, strat.preference))
    return points


def _point(name: str, family: str, rows: Sequence[Mapping[str, Any]],
           preference: tuple[float, ...] | None) -> ParetoPoint:
    """The point of the episodes ``rows`` (at least one) of one strategy."""
    success = 100.0 * sum(bool(r["success"]) for r in rows) / len(rows)
    hours = sum(float(r["sim_time"]) for r in rows) / 3600.0
    rate = sum(int(r["overtakes"]) for r in rows) / hours if hours > 0 else 0.0
    return ParetoPoint(name, family, success, rate, len(rows), preference)


def pareto_front(values: np.ndarray) -> np.ndarray:
    """Indices of the non-dominated rows of ``values`` (n, k), every column maximised, sorted by the
    first column; of identical rows the first is kept."""
    v = np.asarray(values, float).reshape(len(values), -1)
    keep = []
    for i in range(len(v)):
        dominated = np.any(np.all(v >= v[i], axis=1) & np.any(v > v[i], axis=1))
        duplicate = any(np.array_equal(v[j], v[i]) for j in keep)
        if not dominated and not duplicate:
            keep.append(i)
    keep = np.array(keep, dtype=int)
    return keep[np.argsort(v[keep, 0], kind="stable")] if keep.size else keep


def hypervolume(values: np.ndarray, reference: Sequence[float] = REFERENCE_POINT) -> float:
    """Hypervolume of the points ``values`` (n, k) (every column maximised) above ``reference``,
    with pymoo's ``HV`` indicator. Points not better than the reference in every objective add nothing."""
    from pymoo.indicators.hv import HV

    v = np.asarray(values, float).reshape(-1, len(reference))
    ref = np.asarray(reference, float)
    v = v[np.all(v > ref, axis=1)]
    if len(v) == 0:
        return 0.0
    return float(HV(ref_point=-ref)(-v))


def _family_hypervolumes(points: Sequence[ParetoPoint]) -> dict[str, float]:
    """The hypervolume of each family's points (``fixed``, ``policy``, ``baseline``; a family without points is
    left out)."""
    hv = {}
    for family in ("fixed", "policy", "baseline"):
        values = np.array([(p.success, p.overtakes_per_hour) for p in points if p.family == family])
        if len(values):
            hv[family] = hypervolume(values)
    return hv


def plot_fronts(points: Sequence[ParetoPoint], path: str | os.PathLike, title: str = "") -> Path:
    """A PNG of the points of each family and their fronts (staircase lines)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4.6), dpi=110)
    styles = {"fixed": ("tab:blue", "o", "fixed gamma"), "policy": ("tab:red", "s", "PASTA, preference sweep"),
              "baseline": ("tab:green", "^", "PPO (SB3)")}
    for family, (colour, marker, label) in styles.items():
        pts = [p for p in points if p.family == family]
        if not pts:
            continue
        xy = np.array([(p.overtakes_per_hour, p.success) for p in pts])
        ax.scatter(xy[:, 0], xy[:, 1], c=colour, marker=marker, label=label, zorder=3)
        for p, (x, y) in zip(pts, xy):
            ax.annotate(p.name, (x, y), textcoords="offset points", xytext=(4, 4), fontsize=7, color=colour)
        front = xy[pareto_front(xy[:, ::-1])]  # non-dominated in (success, rate)
        front = front[np.argsort(front[:, 0])]  # rate ascending, so success descending
        stair_x, stair_y = [0.0], [front[0, 1]]
        for i, (x, y) in enumerate(front):
            stair_x += [x, x]
            stair_y += [y, front[i + 1, 1] if i + 1 < len(front) else 0.0]
        ax.plot(stair_x, stair_y, color=colour, alpha=0.5, lw=1.2)
    ax.set_xlabel("overtakes per hour of racing")
    ax.set_ylabel("success rate [%]")
    ax.set_ylim(bottom=0.0, top=102.0)
    ax.set_xlim(left=0.0)
    ax.grid(alpha=0.3)
    ax.legend(loc="lower left", fontsize=8)
    if title:
        ax.set_title(title, fontsize=9)
    fig.tight_layout()
    out = Path(path)
    fig.savefig(out)
    plt.close(fig)
    return out


def _markdown(points: Sequence[ParetoPoint], hv: Mapping[str, float], settings: Mapping[str, Any]) -> str:
    lines = ["# Pareto view: success against overtaking", "",
             ", ".join(f"{k} = {v}" for k, v in settings.items()) + ".", "",
             "Both objectives are maximised; a point on its family's front is marked *. Hypervolume: the area "
             "dominated by a front above the reference point (0 %, 0 /h), with pymoo's HV indicator.", "",
             "| strategy | preference (safety, overtakes, ...) | success [%] | overtakes / h | episodes | front |",
             "|---|---|---:|---:|---:|:---:|"]
    for family in ("fixed", "policy", "baseline"):
        pts = [p for p in points if p.family == family]
        on_front = set()
        if pts:
            idx = pareto_front(np.array([(p.success, p.overtakes_per_hour) for p in pts]))
            on_front = {pts[i].name for i in idx}
        for p in pts:
            pref = ", ".join(f"{w:.2f}" for w in p.preference) if p.preference else "-"
            lines.append(f"| {p.name} | {pref} | {p.success:.1f} | {p.overtakes_per_hour:.1f} | {p.episodes} | "
                         f"{'*' if p.name in on_front else ''} |")
    lines += ["", "| front | hypervolume [% x 1/h] |", "|---|---:|"]
    lines += [f"| {family} | {value:.1f} |" for family, value in hv.items()]
    return "\n".join(lines) + "\n"


def pareto_strategies(policy: str | os.PathLike | None, preferences: Sequence[Sequence[float]],
                      gammas: Sequence[float], sb3: str | os.PathLike | None = None) -> list[Strategy]:
    """The strategies of a sweep, in its order: each fixed gamma, then ``policy`` (if given) at each preference,
    named ``pasta w=<the preference's weights, 3 significant digits, joined by />``, then the SB3 policy
    ``sb3`` (if given), named ``PPO (SB3)``."""
    strategies = [Strategy.fixed(g) for g in gammas]
    if policy is not None:
        for pref in preferences:
            label = "pasta w=" + "/".join(f"{w:.3g}" for w in pref)
            strategies.append(Strategy.adaptive(policy, name=label, preference=pref))
    if sb3 is not None:
        strategies.append(Strategy.sb3(sb3, name="PPO (SB3)"))
    return strategies


def run_pareto(policy: str | os.PathLike | None, preferences: Sequence[Sequence[float]], gammas: Sequence[float],
               out_dir: str | os.PathLike, *, tracks: Sequence[str] = TRACKS, rhos: Sequence[float] = RHOS,
               episodes: int = 5, base_seed: int = 0, duration: float = DEFAULT_DURATION,
               workers: int | None = None, progress: bool = True, stack: str = "sofar", scenario: str = "paper",
               backend: str = "local", address: str | None = None, prefix: str = "pareto",
               n_opponents: int | None = None, sb3: str | os.PathLike | None = None) -> ParetoReport:
    """Run (or resume) the sweep of the fixed ``gammas`` and of ``policy`` at each of ``preferences`` into
    ``out_dir/<prefix>_episodes.csv``; write ``<prefix>.md``, ``<prefix>.json``, ``<prefix>.png`` and the
    resolved configuration to ``out_dir/config.json``
    (``n_opponents``: the field size, None for the environment's default of 4; ``sb3``: an SB3 PPO zip
    evaluated as one more point, family ``baseline``)."""
    strategies = pareto_strategies(policy, preferences, gammas, sb3)
    if not strategies:
        raise ValueError("nothing to evaluate: give fixed gammas or a policy")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    tasks = table1_tasks(strategies, tracks, rhos, episodes, base_seed, duration, stack=stack, scenario=scenario,
                         n_opponents=n_opponents)
    csv_path = out / f"{prefix}_episodes.csv"
    write_config_json(out, [episode_config(stack, scenario, float(duration))])
    stats = run_sweep(tasks, csv_path, workers=workers, progress=progress, backend=backend, address=address)
    rows = select_rows(read_episode_csv(csv_path), tasks)
    points = strategy_points(rows, strategies)
    hv = _family_hypervolumes(points)
    settings = {"tracks": ", ".join(tracks), "rho": ", ".join(_fmt_float(r) for r in rhos),
                "episodes per (track, rho)": episodes, "horizon": f"{duration:g} s", "base seed": base_seed,
                "controller": stack, "world": scenario}
    if n_opponents is not None:
        settings["opponents"] = n_opponents
    md = _markdown(points, hv, settings)
    if len(rows) < len(tasks):
        md += f"\n**Incomplete:** {len(tasks) - len(rows)} of {len(tasks)} episodes are missing; rerun to finish.\n"
    paths = {"csv": csv_path, "markdown": out / f"{prefix}.md", "json": out / f"{prefix}.json",
             "png": out / f"{prefix}.png"}
    write_text_atomic(paths["markdown"], md)
    write_json_atomic(paths["json"], {"settings": settings, "hypervolume": hv, "reference_point": REFERENCE_POINT,
                                      "points": [p.__dict__ for p in points]}, trailing_newline=False, indent=2)
    plot_fronts(points, paths["png"], title=f"{scenario} world, {stack} controller")
    return ParetoReport(points, hv, md, stats, paths)


def _family_of(strategy: str) -> str:
    if strategy.startswith("gamma="):
        return "fixed"
    return "baseline" if strategy == "PPO (SB3)" else "policy"


def _preference_of(strategy: str) -> tuple[float, ...] | None:
    if not strategy.startswith("pasta w="):
        return None
    try:
        return tuple(float(w) for w in strategy[len("pasta w="):].split("/"))
    except ValueError:
        return None


def pooled_pareto(csv_paths: Sequence[str | os.PathLike]) -> tuple[list[ParetoPoint], dict[str, float],
                                                                    dict[str, tuple[float, float]], str]:
    """The Pareto view of several ``pareto_episodes.csv`` files of one front (its seed sets), their episodes pooled.

    A strategy is a point only if every file holds it, and then over all their episodes. Returns the points, the
    hypervolume of each family, the mean and standard deviation of the per-episode ``mean_gamma`` of each
    strategy, and a Markdown report. Raises ``ValueError`` when fewer than two files are given, a file is missing,
    given twice or has no rows, the rows of one strategy carry two configuration hashes or controllers, or an
    episode (strategy, circuit, rho, seed) is in two files (:func:`~.results.pool_seed_sets`).
    """
    if len(csv_paths) < 2:
        raise ValueError("pooling needs at least two pareto_episodes.csv files")
    sets = read_seed_sets(csv_paths)
    for name, set_rows in sets.items():
        if not set_rows:
            raise ValueError(f"{name} has no episode rows")
    in_every = set.intersection(*({r["strategy"] for r in set_rows} for set_rows in sets.values()))
    common = [n for n in dict.fromkeys(r["strategy"] for r in next(iter(sets.values()))) if n in in_every]
    rows = [r for r in pool_seed_sets(sets) if r["strategy"] in common]
    for name in common:
        labels = {(r.get("config_hash", ""), r.get("stack", "")) for r in rows if r["strategy"] == name}
        if len(labels) > 1:
            raise ValueError(f"strategy {name!r} has rows of {len(labels)} configurations: {sorted(labels)}")
    points = [_point(n, _family_of(n), [r for r in rows if r["strategy"] == n], _preference_of(n)) for n in common]
    hv = _family_hypervolumes(points)
    gamma = {}
    for name in common:
        means = np.array([float(r["mean_gamma"]) for r in rows if r["strategy"] == name])
        gamma[name] = (float(means.mean()), float(means.std()))
    settings = {"files": ", ".join(str(p) for p in csv_paths), "episodes per point": len(rows) // max(len(common), 1)}
    md = _markdown(points, hv, settings).replace("# Pareto view:", "# Pareto view, seed sets pooled:", 1)
    md += ("\n| strategy | mean gamma | its spread over the episodes (sd of their means) |\n|---|---:|---:|\n"
           + "".join(f"| {n} | {m:.3f} | {sd:.3f} |\n" for n, (m, sd) in gamma.items()))
    return points, hv, gamma, md
