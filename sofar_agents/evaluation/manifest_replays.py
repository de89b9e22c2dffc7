"""The manifest kinds ``pareto``, ``interventions`` and ``figures``: their episodes, how they run and how rows are
named.

``pareto`` runs what ``eval/pareto.py`` runs (:func:`~sofar_agents.evaluation.pareto.run_pareto`: the fixed
gammas, then the policy at each preference, on the Table I protocol's episodes) and its rows are episode rows
as Table I's. ``interventions`` runs what ``eval/interventions.py`` runs
(:func:`~sofar_agents.evaluation.interventions.replay_interventions`: every failed episode of ``base_gamma`` in
the ``sources`` CSVs, replayed once as it was and once per intervention of
:func:`~sofar_agents.evaluation.interventions.default_interventions`); its rows are ``interventions.csv``
rows, one per replay, named by :func:`replay_row_id` and grouped into episodes by :func:`replay_episode`.
``figures`` runs what ``eval/figures.py`` runs (:func:`~sofar_agents.evaluation.figures.record_figure_episodes`,
then the two PNGs of Fig. 5 from the adaptive strategy's trace); its rows are episode rows as Table I's.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from sofar_agents.evaluation.manifest_spec import DEFAULT_SWITCH_GAMMAS, Manifest
from sofar_agents.evaluation.protocol import EpisodeTask

__all__ = ["pareto_tasks", "run_pareto_manifest", "run_pareto_rows", "interventions_of", "failed_tasks",
           "replay_episode", "replay_row_id", "task_episode", "run_interventions_manifest", "run_figures_manifest"]

_REPLAY_ID = ("track", "rho", "seed", "use_miqp", "base_gamma", "kind", "gamma", "window_s", "hold_s", "lead_s")
"""The columns that name one replay in an ``interventions.csv``."""


def pareto_tasks(m: Manifest, root: str | os.PathLike) -> list[EpisodeTask]:
    """The episodes of a pareto manifest, in the order :func:`~sofar_agents.evaluation.pareto.run_pareto` runs
    them."""
    from sofar_agents.evaluation.protocol import table1_tasks

    return table1_tasks(m.strategies(root), m.tracks, m.rhos, m.episode_count, m.seed, m.duration, stack=m.stack,
                        scenario=m.scenario, n_opponents=m.opponents)


def run_pareto_manifest(m: Manifest, root: str | os.PathLike, folder: Path, workers: int | None,
                        progress: bool) -> Any:
    """Run (or resume) a pareto manifest into ``folder`` as ``eval/pareto.py`` does; returns its report."""
    from sofar_agents.evaluation.pareto import preference_family, run_pareto
    from sofar_agents.evaluation.protocol import FIXED_GAMMAS

    return run_pareto(m.policy_path(root) if m.adaptive else None, preference_family(m.safety_weights),
                      FIXED_GAMMAS if m.gammas is None else m.gammas, folder, tracks=m.tracks, rhos=m.rhos,
                      episodes=m.episode_count, base_seed=m.seed, duration=m.duration, workers=workers,
                      progress=progress, stack=m.stack, scenario=m.scenario, prefix=m.prefix or "pareto",
                      n_opponents=m.opponents)


def run_pareto_rows(m: Manifest, root: str | os.PathLike, folder: Path, keep: Callable[[EpisodeTask], bool],
                    workers: int | None) -> None:
    """Run only the episodes of a pareto manifest that ``keep`` keeps into ``folder``'s CSV (no report)."""
    from sofar_agents.evaluation.sweep import run_sweep

    folder.mkdir(parents=True, exist_ok=True)
    run_sweep([t for t in pareto_tasks(m, root) if keep(t)], folder / m.csv_name, workers=workers, progress=False)


def interventions_of(m: Manifest) -> list:
    """The interventions of an interventions manifest (:func:`~.interventions.default_interventions`)."""
    from sofar_agents.evaluation.interventions import default_interventions

    return default_interventions(m.base_gamma, DEFAULT_SWITCH_GAMMAS if m.gammas is None else m.gammas,
                                 m.windows, m.hold, m.placebo_delta, m.placebo_lead)


def failed_tasks(m: Manifest, root: str | os.PathLike) -> list[EpisodeTask]:
    """The failed episodes of ``base_gamma`` in the ``sources`` CSVs (at most ``limit`` per CSV), as
    ``eval/interventions.py`` finds them; ``ValueError`` for an episode of another controller, world or horizon
    than the manifest's, or when there is none."""
    from sofar_agents.evaluation.interventions import failed_episodes
    from sofar_agents.evaluation.results import read_seed_sets

    tasks = []
    for rows in read_seed_sets([Path(root) / s for s in m.sources]).values():
        tasks += failed_episodes(rows, m.base_gamma, m.limit)
    other = {(t.stack, t.scenario, t.duration) for t in tasks} - {(m.stack, m.scenario, float(m.duration))}
    if other:
        raise ValueError(f"manifest {m.name}: its sources hold failed episodes of other settings {sorted(other)}")
    if not tasks:
        raise ValueError(f"manifest {m.name}: no failed episode of gamma {m.base_gamma:g} in its sources")
    return tasks


def task_episode(t: EpisodeTask) -> tuple:
    """What names a replayed episode: ``(track, rho, seed, use_miqp)`` as an ``interventions.csv`` writes them."""
    return t.track, repr(float(t.rho)), str(int(t.seed)), str(int(t.use_miqp))


def replay_episode(row: Mapping[str, str]) -> tuple:
    """:func:`task_episode` of the episode an ``interventions.csv`` row replayed."""
    return row["track"], repr(float(row["rho"])), row["seed"], row["use_miqp"]


def replay_row_id(row: Mapping[str, str]) -> tuple:
    """What names one replay (row) of an ``interventions.csv``: the episode, base gamma and intervention."""
    return tuple(row[c] for c in _REPLAY_ID)


def run_interventions_manifest(m: Manifest, root: str | os.PathLike, folder: Path, workers: int | None,
                               progress: bool, keep: Callable[[EpisodeTask], bool] | None = None) -> Any:
    """Run (or resume) the replays of an interventions manifest into ``folder/interventions.csv`` and write
    ``interventions.md`` as ``eval/interventions.py`` does (its last paragraph names the manifest instead of the
    command); ``keep``: only the episodes it keeps, and no report. Returns the report (``markdown``, ``stats``;
    None with ``keep``); ``RuntimeError`` when episodes are left unfinished."""
    import time
    from types import SimpleNamespace

    from sofar_agents.evaluation import interventions as iv
    from sofar_agents.evaluation.results import write_markdown

    tasks = failed_tasks(m, root)
    if keep is not None:
        tasks = [t for t in tasks if keep(t)]
    t0 = time.perf_counter()
    results, stats = iv.replay_interventions(tasks, interventions_of(m), folder / m.csv_name, workers=workers or 1,
                                             progress=progress)
    if stats.unfinished:
        raise RuntimeError(f"manifest {m.name}: {stats.unfinished} of {stats.requested} failed episodes did not "
                           f"finish; rerun to resume")
    if keep is not None:
        return None
    text = iv.format_interventions(iv.summarize_interventions(results), m.base_gamma, iv.placebo_comparisons(results))
    text += (f"\n{len(results)} replays, {sum(r.steps for r in results):,} env steps, "
             f"{time.perf_counter() - t0:.0f} s on {workers or 1} worker(s). "
             f"Manifest: `python eval/manifest.py run {m.name}`\n")
    write_markdown(folder / "interventions.md", text)
    return SimpleNamespace(markdown=text, stats=stats)


def run_figures_manifest(m: Manifest, root: str | os.PathLike, folder: Path, workers: int | None, progress: bool,
                         keep: Callable[[EpisodeTask], bool] | None = None) -> Any:
    """Run (or resume) the episodes of a figures manifest into ``folder`` (``episodes.csv``, ``trace.csv``) and draw
    Fig. 5 there from the adaptive strategy's steps, as ``eval/figures.py`` does; ``keep``: only the episodes it
    keeps, and no figure. Returns the report (``markdown``: the gamma summary; None with ``keep``);
    ``RuntimeError`` when episodes are left unfinished."""
    from types import SimpleNamespace

    from sofar_agents.evaluation.figures import (FIGURE_TRACE, gamma_summary, plot_gamma_figures,
                                                 record_figure_episodes)
    from sofar_agents.evaluation.results import read_trace_csv

    stats = record_figure_episodes(m.strategies(root), folder, tracks=m.tracks, rhos=m.rhos,
                                   episodes=m.episode_count, seed=m.seed, duration=m.duration, stack=m.stack,
                                   scenario=m.scenario, n_opponents=m.opponents, workers=workers, progress=progress,
                                   tasks_filter=keep)
    if stats.unfinished:
        raise RuntimeError(f"manifest {m.name}: {stats.unfinished} episodes did not finish; rerun to resume")
    if keep is not None:
        return None
    trace = read_trace_csv(folder / FIGURE_TRACE, strategy="adaptive")
    plot_gamma_figures(trace, folder)
    return SimpleNamespace(markdown=gamma_summary(trace), stats=stats)
