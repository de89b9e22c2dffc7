"""Success and solver failures against gamma: the threshold sweep of the bug-compatible controller.

The sweep (``eval/reference_numerics.py sweep``) runs Table I's episodes at a fine grid of fixed gammas
under ``stack="reference-numerics"`` and, on the same seeded episodes, under the control preset
``"reference-numerics-no-phantoms"``, which differs in one defect only. Per preset and gamma this module
counts episodes, successes, episodes with at least one failed MPC solve, and failed episodes that had a
solver failure before they ended (the CSV's ``mpc_failures`` counts failures up to the episode's end, so
a failed episode with failures had them before it failed). The paired difference between the two presets
at each gamma (exact McNemar test, :mod:`~sofar_agents.evaluation.paired`) is the effect of the phantom
opponents; a *cliff* is an edge of the gamma range where that effect, or the share of episodes with solver
failures, changes from none to some.
"""

from __future__ import annotations

import math
from collections import defaultdict
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from .paired import PairedComparison, label_by_stack, paired_comparison
from .protocol import LEGACY_STACK

__all__ = ["GammaPoint", "PREDICTED_THRESHOLDS", "sweep_points", "phantom_effects", "failure_excess", "failure_edges",
           "format_sweep", "plot_sweep", "wilson_interval"]

PREDICTED_THRESHOLDS = (0.0564, 0.900)
"""Where the hypothesis puts the edges of the failure zones: a phantom row binds for gamma below 0.0564
(the ego accelerating while 4.5-12.8 m/s faster than the phantom), and violates its -1e9 bound for gamma
above 0.900 (the ego not faster than the phantom, h = 1.11e9)."""


def wilson_interval(k: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """Wilson score interval of a binomial proportion ``k / n`` (95 % by default); (nan, nan) for n = 0."""
    if n == 0:
        return math.nan, math.nan
    p = k / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return max(0.0, centre - half), min(1.0, centre + half)


@dataclass(frozen=True)
class GammaPoint:
    """One (preset, gamma) of the sweep."""

    stack: str
    gamma: float
    episodes: int
    successes: int
    solver_failure_episodes: int
    """Episodes with at least one failed MPC solve."""
    failed_with_solver_failure: int
    """Failed episodes (collision, off-track, stall) that had a failed MPC solve before they ended."""
    mpc_failures: int
    """Failed MPC solves, summed over the episodes."""

    @property
    def success_rate(self) -> float:
        return self.successes / self.episodes if self.episodes else math.nan

    @property
    def failure_episode_rate(self) -> float:
        return self.solver_failure_episodes / self.episodes if self.episodes else math.nan

    @property
    def failed(self) -> int:
        return self.episodes - self.successes


def _gamma(strategy: str) -> float | None:
    return float(strategy.split("=", 1)[1]) if strategy.startswith("gamma=") else None


def sweep_points(rows: Iterable[Mapping[str, Any]]) -> list[GammaPoint]:
    """The fixed-gamma rows grouped by (preset, gamma), sorted by preset then gamma."""
    acc: dict[tuple[str, float], list[int]] = defaultdict(lambda: [0, 0, 0, 0, 0])
    for r in rows:
        g = _gamma(str(r["strategy"]))
        if g is None:
            continue
        a = acc[(str(r.get("stack") or LEGACY_STACK), g)]
        ok, fails = bool(r["success"]), int(float(r.get("mpc_failures") or 0))
        a[0] += 1
        a[1] += ok
        a[2] += fails > 0
        a[3] += (not ok) and fails > 0
        a[4] += fails
    return [GammaPoint(s, g, *v) for (s, g), v in sorted(acc.items())]


def phantom_effects(rows: Iterable[Mapping[str, Any]], stack: str, control: str) -> dict[float, PairedComparison]:
    """Per gamma, ``stack`` against ``control`` on the episodes both ran (paired by circuit, rho, seed)."""
    rows = list(rows)
    sets = label_by_stack({"sweep": rows})
    gammas = sorted({g for r in rows if (g := _gamma(str(r["strategy"]))) is not None})
    out = {}
    for g in gammas:
        strategy = next(str(r["strategy"]) for r in rows if _gamma(str(r["strategy"])) == g)
        try:
            out[g] = paired_comparison(sets, f"{stack}:{strategy}", f"{control}:{strategy}")
        except ValueError:  # one of the presets has not run this gamma
            continue
    return out


def _failure_flags(rows: Iterable[Mapping[str, Any]], stack: str) -> dict[float, dict[tuple, bool]]:
    """Per gamma of ``stack``: episode (circuit, rho, seed) -> whether it had a failed MPC solve."""
    out: dict[float, dict[tuple, bool]] = defaultdict(dict)
    for r in rows:
        g = _gamma(str(r["strategy"]))
        if g is None or str(r.get("stack") or LEGACY_STACK) != stack:
            continue
        out[g][(str(r["track"]), round(float(r["rho"]), 6), int(r["seed"]))] = int(float(r.get("mpc_failures") or 0)) > 0
    return out


def failure_excess(rows: Iterable[Mapping[str, Any]], stack: str, reference: float = 0.5) -> dict[float, tuple]:
    """Per gamma of ``stack``: ``(episodes, with failures, with failures at the reference gamma, p)``, p the
    two-sided exact McNemar test of "had a failed solve" against the reference gamma on the same episodes."""
    from scipy.stats import binomtest

    flags = _failure_flags(rows, stack)
    if reference not in flags:
        raise ValueError(f"no episodes of {stack!r} at the reference gamma {reference}")
    ref = flags[reference]
    out = {}
    for g, f in sorted(flags.items()):
        common = f.keys() & ref.keys()
        only_g = sum(f[k] and not ref[k] for k in common)
        only_ref = sum(ref[k] and not f[k] for k in common)
        p = 1.0 if only_g + only_ref == 0 else float(binomtest(only_g, only_g + only_ref, 0.5).pvalue)
        out[g] = (len(common), sum(f[k] for k in common), sum(ref[k] for k in common), p)
    return out


def failure_edges(rows: Iterable[Mapping[str, Any]], stack: str, reference: float = 0.5,
                  alpha: float = 0.05) -> tuple[tuple, tuple]:
    """``((low_in, low_out), (high_out, high_in))``: walking down (up) the grid from ``reference``, the first
    gamma whose share of episodes with failed solves is higher than at ``reference`` with paired p < ``alpha``
    (:func:`failure_excess`), and its neighbour towards ``reference``: the edge of a failure zone lies between
    the two. ``(None, None)`` on a side with no such gamma."""
    ex = failure_excess(rows, stack, reference)
    grid = sorted(ex)
    mid = grid.index(reference)

    def excess(g: float) -> bool:
        n, k, k_ref, p = ex[g]
        return k > k_ref and p < alpha

    low = next(((grid[i], grid[i + 1]) for i in range(mid - 1, -1, -1) if excess(grid[i])), (None, None))
    high = next(((grid[i - 1], grid[i]) for i in range(mid + 1, len(grid)) if excess(grid[i])), (None, None))
    return low, high


def format_sweep(points: Sequence[GammaPoint], effects: Mapping[float, PairedComparison] | None = None,
                 stack: str = "reference-numerics", control: str = "reference-numerics-no-phantoms") -> str:
    """A Markdown table: per gamma, both presets' success and solver failures, and the paired effect."""
    by = {(p.stack, p.gamma): p for p in points}
    gammas = sorted({p.gamma for p in points})
    lines = [f"| γ | success {stack} [%] (95 % CI) | episodes with solver failures | failed episodes with a solver "
             f"failure | success {control} [%] | episodes with solver failures (control) | phantoms − control "
             f"[points] | p (exact McNemar) | episodes |",
             "|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]

    def rate(p: GammaPoint | None) -> str:
        if p is None:
            return "–"
        lo, hi = wilson_interval(p.successes, p.episodes)
        return f"{100 * p.success_rate:.0f} ({100 * lo:.0f}–{100 * hi:.0f})"

    for g in gammas:
        a, c = by.get((stack, g)), by.get((control, g))
        e = (effects or {}).get(g)
        lines.append(
            f"| {g:g} | {rate(a)} | {a.solver_failure_episodes if a else '–'} "
            f"| {f'{a.failed_with_solver_failure} of {a.failed}' if a else '–'} "
            f"| {rate(c)} | {c.solver_failure_episodes if c else '–'} "
            f"| {f'{100 * e.difference:+.0f}' if e else '–'} | {f'{e.p_value:.3g}' if e else '–'} "
            f"| {a.episodes if a else (c.episodes if c else 0)} |")
    return "\n".join(lines) + "\n"


def plot_sweep(points: Sequence[GammaPoint], path, stack: str = "reference-numerics",
               control: str = "reference-numerics-no-phantoms") -> None:
    """Success rate and share of episodes with solver failures against gamma, both presets, with the
    predicted thresholds; written to ``path`` (PNG)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    grid = sorted({p.gamma for p in points})
    pos = {g: i for i, g in enumerate(grid)}  # the grid evenly spaced: both ends of the range readable

    def where(t: float) -> float:  # a threshold between two grid points, placed linearly between them
        import numpy as np

        return float(np.interp(t, grid, range(len(grid))))

    fig, axes = plt.subplots(1, 2, figsize=(12, 4), sharex=True)
    for name, style in ((stack, "o-"), (control, "s--")):
        pts = sorted((p for p in points if p.stack == name), key=lambda p: p.gamma)
        if not pts:
            continue
        x = [pos[p.gamma] for p in pts]
        axes[0].plot(x, [100 * p.success_rate for p in pts], style, label=name, ms=4)
        axes[1].plot(x, [100 * p.failure_episode_rate for p in pts], style, label=name, ms=4)
    for ax, title in zip(axes, ("success [% of episodes]", "episodes with a failed MPC solve [%]")):
        for t in PREDICTED_THRESHOLDS:
            ax.axvline(where(t), color="grey", lw=0.8, ls=":")
        ax.set_xticks(range(len(grid)), [f"{g:g}" for g in grid], fontsize=7, rotation=60)
        ax.set_xlabel("fixed γ (grid points evenly spaced)")
        ax.set_title(title)
        ax.set_ylim(-3, 103)
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    fig.suptitle("Bug-compatible controller: dotted lines are the predicted thresholds 0.0564 and 0.900", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
