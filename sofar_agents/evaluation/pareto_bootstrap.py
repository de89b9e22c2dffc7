"""How far a difference of hypervolumes is from the noise of its episodes: a paired, stratified bootstrap.

Two fronts of a Pareto view (:mod:`.pareto`), say the fixed gammas' and the policy's, are measured on the same
seeded episodes, so their hypervolumes share the episodes' luck. The bootstrap draws the episodes again, with
replacement and within each (circuit, rho) cell of the protocol, keeps every strategy on the same draw (paired),
re-computes every point (success %, overtakes per hour) and each family's hypervolume, and reports the spread of
the difference. Its question: would the sign of the difference survive another draw of episodes like these? It
does not cover training luck (another training seed) or another world.

Contract of :func:`bootstrap_hypervolume`: an episode is (circuit, rho, seed); every strategy must have run every
episode exactly once (else ``ValueError`` naming what is missing); the draws come from ``numpy``'s generator of
``seed``, so a report is re-made to the digit by the same command.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from sofar_agents.evaluation.pareto import _family_of, hypervolume

__all__ = ["HypervolumeBootstrap", "bootstrap_hypervolume", "bootstrap_markdown"]


@dataclass(frozen=True)
class HypervolumeBootstrap:
    """The hypervolume of two families, observed and over ``resamples`` paired draws of the episodes."""

    families: tuple[str, str]
    """(a, b): the difference is ``b - a`` (e.g. ``("fixed", "policy")``)."""
    strategies: dict[str, tuple[str, ...]]
    """The strategies of each family."""
    episodes: int
    """Episodes per strategy."""
    cells: int
    """(circuit, rho) cells the draws keep."""
    observed: tuple[float, float]
    """Hypervolume of a and of b on the episodes as run."""
    resamples: int
    seed: int
    differences: np.ndarray
    """``b - a`` on each draw."""

    @property
    def difference(self) -> float:
        """Observed ``b - a``."""
        return self.observed[1] - self.observed[0]

    @property
    def relative(self) -> float:
        """Observed ``b / a - 1``."""
        return self.observed[1] / self.observed[0] - 1.0 if self.observed[0] > 0 else float("nan")

    def interval(self, level: float = 0.95) -> tuple[float, float]:
        """Percentile interval of ``b - a`` holding ``level`` of the draws."""
        if not 0.0 < level < 1.0:
            raise ValueError(f"level must lie in (0, 1), got {level!r}")
        lo, hi = np.quantile(self.differences, [(1.0 - level) / 2.0, (1.0 + level) / 2.0])
        return float(lo), float(hi)

    @property
    def share_b_at_least_a(self) -> float:
        """Share of the draws on which b's hypervolume is at least a's."""
        return float(np.mean(self.differences >= 0.0))


def _episode_table(rows: Sequence[Mapping[str, Any]], strategies: Sequence[str]):
    """Per strategy, arrays (success, overtakes, sim_time) over one common order of the episodes, and the cell of
    each episode."""
    by_strategy: dict[str, dict[tuple, Mapping[str, Any]]] = {s: {} for s in strategies}
    for r in rows:
        name = r["strategy"]
        if name not in by_strategy:
            continue
        key = (str(r["track"]), float(r["rho"]), int(r["seed"]))
        if key in by_strategy[name]:
            raise ValueError(f"strategy {name!r} ran episode {key} twice")
        by_strategy[name][key] = r
    keys = sorted(by_strategy[strategies[0]])
    for name in strategies:
        if set(by_strategy[name]) != set(keys):
            missing = sorted(set(keys) ^ set(by_strategy[name]))[:3]
            raise ValueError(f"strategy {name!r} did not run the same episodes as {strategies[0]!r} "
                             f"(e.g. {missing}): the bootstrap pairs strategies on shared episodes")
    table = {name: np.array([(float(bool(int(float(by_strategy[name][k]["success"])))),
                              float(by_strategy[name][k]["overtakes"]), float(by_strategy[name][k]["sim_time"]))
                             for k in keys]) for name in strategies}
    cells = [(k[0], k[1]) for k in keys]
    return table, cells


def _draw_episodes(cells: Sequence[tuple], resamples: int, rng: np.random.Generator) -> tuple[np.ndarray, int]:
    """(resamples, episodes): how often each draw takes each episode, drawing with replacement within each cell
    (``cells[i]`` the cell of episode i), and the number of cells."""
    cell_index: dict[tuple, list[int]] = {}
    for i, c in enumerate(cells):
        cell_index.setdefault(c, []).append(i)
    counts = np.zeros((resamples, len(cells)))
    rows_of_draws = np.arange(resamples)[:, None]
    for idx in cell_index.values():
        draws = rng.choice(np.asarray(idx), size=(resamples, len(idx)), replace=True)
        np.add.at(counts, (rows_of_draws, draws), 1.0)
    return counts, len(cell_index)


def _points(counts: np.ndarray, data: np.ndarray) -> np.ndarray:
    """(draws, 2): success [%] and overtakes per hour of one strategy on each draw (``counts``: (draws, episodes),
    how often each episode is drawn)."""
    n = counts.sum(axis=1)
    success = 100.0 * (counts @ data[:, 0]) / n
    hours = (counts @ data[:, 2]) / 3600.0
    rate = np.divide(counts @ data[:, 1], hours, out=np.zeros_like(hours), where=hours > 0)
    return np.stack([success, rate], axis=1)


def bootstrap_hypervolume(rows: Sequence[Mapping[str, Any]], families: tuple[str, str] = ("fixed", "policy"),
                          resamples: int = 2000, seed: int = 0) -> HypervolumeBootstrap:
    """The paired, stratified bootstrap of ``hypervolume(b) - hypervolume(a)`` (module docstring).

    ``rows``: episode rows of one front (one seed set or several pooled); the family of a strategy is read from
    its name as in :func:`~.pareto.pooled_pareto`. Raises ``ValueError`` when a family has no strategy,
    ``resamples`` < 100, or the strategies did not run the same episodes.
    """
    if int(resamples) != resamples or resamples < 100:
        raise ValueError(f"resamples must be an integer >= 100, got {resamples!r}")
    if len(families) != 2 or families[0] == families[1]:
        raise ValueError(f"families must be two different names, got {families!r}")
    names = list(dict.fromkeys(r["strategy"] for r in rows))
    members = {f: tuple(n for n in names if _family_of(n) == f) for f in families}
    for f, m in members.items():
        if not m:
            raise ValueError(f"no strategy of family {f!r} in the rows (strategies: {names})")
    strategies = [n for f in families for n in members[f]]
    table, cells = _episode_table(rows, strategies)
    n_ep = len(cells)
    counts, n_cells = _draw_episodes(cells, int(resamples), np.random.default_rng(seed))
    points = {n: _points(counts, table[n]) for n in strategies}
    ones = np.ones((1, n_ep))
    observed = tuple(hypervolume(np.vstack([_points(ones, table[n]) for n in members[f]])) for f in families)
    diffs = np.empty(int(resamples))
    for b in range(int(resamples)):
        hv_a, hv_b = (hypervolume(np.array([points[n][b] for n in members[f]])) for f in families)
        diffs[b] = hv_b - hv_a
    return HypervolumeBootstrap(tuple(families), members, n_ep, n_cells, observed, int(resamples),
                                int(seed), diffs)


def bootstrap_markdown(result: HypervolumeBootstrap, sources: Sequence[str], level: float = 0.95) -> str:
    """A Markdown report of ``result`` (``sources``: the files its rows came from)."""
    a, b = result.families
    lo, hi = result.interval(level)
    ha, hb = result.observed
    rel = lambda x: 100.0 * x / ha if ha > 0 else float("nan")  # noqa: E731
    lines = [f"# Hypervolume of the {b} front against the {a} front: paired bootstrap over the episodes", "",
             f"Rows: {', '.join(sources)}. {result.episodes} episodes per strategy in {result.cells} (circuit, rho) "
             f"cells; {result.resamples} draws of the episodes with replacement within each cell, every strategy on "
             f"the same draw; generator seed {result.seed}. Strategies: {a}: {', '.join(result.strategies[a])}; "
             f"{b}: {', '.join(result.strategies[b])}.", "",
             "| | value |", "|---|---:|",
             f"| hypervolume {a} [% x 1/h] | {ha:,.0f} |",
             f"| hypervolume {b} [% x 1/h] | {hb:,.0f} |",
             f"| {b} - {a} | {result.difference:+,.0f} ({rel(result.difference):+.1f} %) |",
             f"| {100 * level:g} % interval of {b} - {a} (percentile) | {lo:+,.0f} to {hi:+,.0f} "
             f"({rel(lo):+.1f} to {rel(hi):+.1f} %) |",
             f"| share of draws with {b} >= {a} | {100 * result.share_b_at_least_a:.1f} % |",
             f"| sd of {b} - {a} over the draws | {result.differences.std(ddof=1):,.0f} |", "",
             "The draws cover the luck of the episodes, not of training (another training seed) or of the world.", ""]
    return "\n".join(lines)
