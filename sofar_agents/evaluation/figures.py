"""The paper's Fig. 5: gamma histogram and nearest-opponent distance vs gamma, from a trace."""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path

import numpy as np


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
