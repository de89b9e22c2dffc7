"""Tables I and II end to end: tasks -> sweep (resumed) -> rows -> Markdown report on disk.

Every table's folder also gets ``config.json``: the resolved configuration of the hash its rows carry
(:func:`~sofar_agents.evaluation.configs.write_config_json`, before any episode runs). Rows of the CSV that
match the table's episodes but carry another configuration hash (or none: files written before the hash)
are left out of the table and counted in its text.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from sofar_agents.evaluation.protocol import (DEFAULT_DURATION, RHOS, TRACKS, Strategy, _fmt_float,
                                              miqp_ablation_tasks, table1_tasks)
from sofar_agents.evaluation.configs import episode_config, write_config_json
from sofar_agents.evaluation.files import write_text_atomic
from sofar_agents.evaluation.results import read_episode_csv, rows_of_other_configs, select_rows
from sofar_agents.evaluation.sweep import SweepStats, run_sweep
from sofar_agents.evaluation.tables import format_table1, format_table2, paper_comparison


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
            f"with {stats.workers} worker{'' if stats.workers == 1 else 's'} in {stats.elapsed:.0f} s: "
            f"{stats.steps} control steps, "
            f"{rate:.0f} steps/s per worker.")


def run_table1(strategies: Sequence[Strategy], out_dir: str | os.PathLike = "results", *,
               tracks: Sequence[str] = TRACKS, rhos: Sequence[float] = RHOS, episodes: int = 5, base_seed: int = 0,
               duration: float = DEFAULT_DURATION, workers: int | None = None, trace: bool = False,
               progress: bool = True, prefix: str = "table1", stack: str = "sofar", scenario: str = "paper",
               backend: str = "local", address: str | None = None,
               n_opponents: int | None = None, tasks_filter: Callable[[Any], bool] | None = None) -> TableReport:
    """Table I: run (or resume) the sweep into ``out_dir/<prefix>_episodes.csv``, write ``<prefix>.md``.

    ``workers``, ``backend`` and ``address`` go to :func:`~sofar_agents.evaluation.sweep.run_sweep`;
    ``n_opponents`` sets the field size (None: the environment's default, 4). With ``trace``, the per-step trace of the non-fixed strategies goes to ``<prefix>_trace.csv``.
    ``tasks_filter``: run and show only the episodes it keeps (re-making chosen rows, see
    :func:`~sofar_agents.evaluation.manifest.rerun_rows`).
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    tasks = table1_tasks(strategies, tracks, rhos, episodes, base_seed, duration,
                         trace=(lambda s: s.kind != "fixed") if trace else False, stack=stack,
                         scenario=scenario, n_opponents=n_opponents)
    if tasks_filter is not None:
        tasks = [t for t in tasks if tasks_filter(t)]
    csv_path = out / f"{prefix}_episodes.csv"
    write_config_json(out, [episode_config(stack, scenario, float(duration))])
    stats = run_sweep(tasks, csv_path, workers=workers, progress=progress,
                      trace_path=out / f"{prefix}_trace.csv" if trace else None, backend=backend, address=address)
    all_rows = read_episode_csv(csv_path)
    rows = select_rows(all_rows, tasks)
    settings = {"tracks": ", ".join(tracks), "rho": ", ".join(_fmt_float(r) for r in rhos),
                "episodes per (track, rho)": episodes, "horizon": f"{duration:g} s", "base seed": base_seed,
                "controller": stack, "world": scenario, "config hash": tasks[0].config_hash if tasks else "–"}
    if n_opponents is not None:
        settings["opponents"] = n_opponents
    parts = [_run_header("Table I: performance per circuit", settings),
             "Per circuit and metric, **bold** is the best and <u>underlined</u> the second best "
             "(success rate, simulated time, laps, overtakes: higher is better). Slack: percentage of control "
             "steps in which the MPC used DCBF slack.\n",
             format_table1(rows, strategies, tracks)]
    cmp = paper_comparison(rows, strategies)
    if cmp:
        parts += ["\n## Success rate next to the paper's Table I\n", cmp]
    return _write_report(parts, tasks, rows, stats, csv_path, out / f"{prefix}.md", all_rows)


def _write_report(parts: list[str], tasks, rows, stats, csv_path: Path, md_path: Path,
                  all_rows: Sequence[Mapping[str, Any]] = ()) -> TableReport:
    """Append the rows left out for their configuration, the completeness line and the sweep statistics to
    ``parts``, write the Markdown file."""
    for h, n in sorted(rows_of_other_configs(all_rows, tasks).items()):
        what = f"config hash {h}" if h else "no config hash (written before the column)"
        parts.append(f"\n**Left out:** {n} rows of {csv_path.name} with {what}: episodes of another "
                     "configuration, not mixed with these.")
    missing = len(tasks) - len(rows)
    if missing:
        parts.append(f"\n**Incomplete:** {missing} of {len(tasks)} episodes are missing; rerun the same command "
                     "to finish them.")
    parts.append("\n" + _stats_text(stats))
    md = "\n".join(parts) + "\n"
    write_text_atomic(md_path, md)
    return TableReport(md, stats, csv_path, md_path, rows)


def run_miqp_ablation(strategies: Sequence[Strategy], out_dir: str | os.PathLike = "results", *,
                      episodes: int = 10, rhos: Sequence[float] = RHOS, track: str = "LagunaSeca",
                      base_seed: int = 0, duration: float = DEFAULT_DURATION, workers: int | None = None,
                      progress: bool = True, prefix: str = "table2", stack: str = "sofar",
                      scenario: str = "paper", backend: str = "local",
                      address: str | None = None, tasks_filter: Callable[[Any], bool] | None = None) -> TableReport:
    """Table II: ``track`` with and without the MIQP layer, into ``out_dir/<prefix>_episodes.csv`` and ``.md``.

    ``workers``, ``backend`` and ``address`` go to :func:`~sofar_agents.evaluation.sweep.run_sweep`;
    ``tasks_filter`` as in :func:`run_table1`.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    tasks = miqp_ablation_tasks(strategies, episodes, rhos, track, base_seed, duration, stack=stack,
                                scenario=scenario)
    if tasks_filter is not None:
        tasks = [t for t in tasks if tasks_filter(t)]
    csv_path = out / f"{prefix}_episodes.csv"
    write_config_json(out, [episode_config(stack, scenario, float(duration))])
    stats = run_sweep(tasks, csv_path, workers=workers, progress=progress, backend=backend, address=address)
    all_rows = read_episode_csv(csv_path)
    rows = select_rows(all_rows, tasks)
    settings = {"track": track, "rho cycled over": ", ".join(_fmt_float(r) for r in rhos),
                "episodes per (setting, strategy)": episodes, "horizon": f"{duration:g} s", "base seed": base_seed,
                "controller": stack, "world": scenario, "config hash": tasks[0].config_hash if tasks else "–"}
    parts = [_run_header("Table II: with and without the MIQP layer", settings),
             "**Bold** is the best and <u>underlined</u> the second best over the four rows (as in the paper).\n",
             format_table2(rows, strategies)]
    return _write_report(parts, tasks, rows, stats, csv_path, out / f"{prefix}.md", all_rows)
