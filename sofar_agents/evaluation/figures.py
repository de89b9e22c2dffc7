"""The paper's Fig. 5: gamma histogram and nearest-opponent distance vs gamma, from a trace.

:func:`record_figure_episodes` runs (or resumes) the episodes of a figure into ``<out>/episodes.csv`` and their
per-step trace into ``<out>/trace.csv`` (what ``eval/figures.py`` and a ``figures`` manifest run);
:func:`plot_gamma_figures` draws the two PNGs from a trace.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["FIGURE_EPISODES", "FIGURE_TRACE", "record_figure_episodes", "gamma_summary", "plot_gamma_figures"]

FIGURE_EPISODES = "episodes.csv"
"""The episode rows of a figure's folder (as Table I's rows)."""
FIGURE_TRACE = "trace.csv"
"""The per-step trace of a figure's episodes."""


def record_figure_episodes(strategies: Sequence[Any], out_dir: str | os.PathLike, *, tracks: Sequence[str],
                           rhos: Sequence[float], episodes: int, seed: int, duration: float, stack: str,
                           scenario: str, n_opponents: int | None = None, workers: int | None = None,
                           backend: str = "local", address: str | None = None, progress: bool = True,
                           tasks_filter: Callable[[Any], bool] | None = None) -> Any:
    """Run (or resume) the Table I episodes of ``strategies`` on ``tracks`` x ``rhos`` (``episodes`` each, base
    seed ``seed``) with a per-step trace of every strategy: rows to ``out_dir/episodes.csv``, steps to
    ``out_dir/trace.csv``, the resolved configuration to ``config.json``. The trace rows carry no policy id, so a
    folder that holds another policy's adaptive episodes is refused (``ValueError``) before anything runs.
    ``tasks_filter`` keeps only some episodes (re-making chosen rows). Returns the sweep's statistics."""
    from sofar_agents.evaluation.configs import episode_config, write_config_json
    from sofar_agents.evaluation.protocol import table1_tasks
    from sofar_agents.evaluation.results import read_episode_csv
    from sofar_agents.evaluation.sweep import run_sweep

    out = Path(out_dir)
    recorded = out / FIGURE_EPISODES
    mine = {s.policy_id for s in strategies if s.kind != "fixed"}
    others = sorted({str(r["policy_id"]) for r in (read_episode_csv(recorded) if recorded.exists() else [])
                     if r["strategy"] == "adaptive"} - mine)
    if others:
        raise ValueError(f"{out} holds the episodes of another policy ({', '.join(others)}); use another folder, "
                         f"or delete {recorded} and {out / FIGURE_TRACE} to record this one")
    tasks = table1_tasks(strategies, tracks, rhos, episodes, seed, duration, trace=True, stack=stack,
                         scenario=scenario, n_opponents=n_opponents)
    if tasks_filter is not None:
        tasks = [t for t in tasks if tasks_filter(t)]
    out.mkdir(parents=True, exist_ok=True)
    write_config_json(out, [episode_config(stack, scenario, float(duration))])
    return run_sweep(tasks, recorded, workers=workers, trace_path=out / FIGURE_TRACE, progress=progress,
                     backend=backend, address=address)


def gamma_summary(trace: Mapping[str, np.ndarray]) -> str:
    """One line on the gammas of a trace: steps, mean, median and the 5-95 % range."""
    g = np.asarray(trace["gamma"], float)
    return (f"{g.size} steps: gamma mean {g.mean():.3f}, median {np.median(g):.3f}, "
            f"5-95% [{np.percentile(g, 5):.3f}, {np.percentile(g, 95):.3f}]")


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
