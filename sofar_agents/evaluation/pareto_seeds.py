"""A training recipe's front over several training seeds, against the fixed gammas on the same episodes.

One trained policy is one draw of its recipe: two training seeds of one recipe can lie further apart than two
recipes. Given the Pareto files (``pareto_episodes.csv``) of k >= 2 policies trained by one recipe with different
seeds, each evaluated on the same seeded episodes as the same fixed gammas, :func:`training_seed_fronts` reports

* each seed's front and its hypervolume against the fixed gammas' (as ``eval/pareto.py`` reports one file), and
  **the recipe's difference: the mean over the seeds of ``hv(seed) - hv(fixed)``**. Each seed's points rest on as
  many episodes as the fixed gammas', so both fronts carry the same noise (a front's hypervolume grows with the
  noise of its points: it keeps the lucky ones);
* two paired bootstraps of that mean: over the episodes (the k policies kept, episodes drawn with replacement
  within each (circuit, rho) cell, every strategy on the same draw, as :mod:`~.pareto_bootstrap`), and over the
  training seeds and the episodes (the k policies drawn with replacement as well): the second adds training luck,
  with the resolution k allows (k = 3 gives ten distinct multisets);
* the **pooled front**, descriptive: at each preference, the point of all k policies' episodes together (a policy
  drawing one of the trained ones per episode). Its points rest on k times the episodes of a fixed gamma's, so its
  hypervolume is not compared with theirs as an estimate of the recipe's: it shows what the seeds share.

Contract: every file holds the same fixed-gamma rows (strategy, episode and outcome equal: the fixed rows are run
once and copied), the same policy strategies (preferences), one policy per file and a different one in each
(``policy_id``), one configuration hash over all rows, and every strategy runs every episode once; otherwise
``ValueError`` naming what differs. The draws come from ``numpy``'s generator of ``seed``: a report is re-made to
the digit by the same command.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from sofar_agents.evaluation.pareto import ParetoPoint, _family_of, _point, _preference_of, hypervolume
from sofar_agents.evaluation.pareto_bootstrap import _draw_episodes, _episode_table, _points

__all__ = ["TrainingSeedFronts", "training_seed_fronts", "training_seeds_markdown"]

_SEP = "#"  # a policy strategy of file i is renamed "<name>#<i>" inside the episode table


@dataclass(frozen=True)
class TrainingSeedFronts:
    """The fronts of k policies of one recipe and of the recipe, against the fixed gammas (module docstring)."""

    sources: tuple[str, ...]
    """The files, one per training seed."""
    policy_ids: tuple[str, ...]
    """The policy of each file."""
    fixed: tuple[ParetoPoint, ...]
    """The fixed gammas' points (the same in every file)."""
    per_seed: tuple[tuple[ParetoPoint, ...], ...]
    """Each file's policy points, in preference order."""
    pooled: tuple[ParetoPoint, ...]
    """The pooled front's points: each preference over the episodes of all k policies (descriptive)."""
    mean_gamma: tuple[tuple[float, ...], ...]
    """Per file and preference, the mean over the episodes of the episode's mean gamma."""
    hv_fixed: float
    hv_seeds: tuple[float, ...]
    hv_pooled: float
    episodes: int
    """Episodes per strategy and file."""
    cells: int
    resamples: int
    seed: int
    diff_episodes: np.ndarray
    """The mean over the seeds of ``hv(seed) - hv(fixed)`` on each draw of the episodes (the k policies kept)."""
    diff_seeds_episodes: np.ndarray
    """The same on each draw of the training seeds and of the episodes."""

    @property
    def difference(self) -> float:
        """The recipe's difference: the mean over the seeds of ``hv(seed) - hv(fixed)``."""
        return float(np.mean(self.hv_seeds)) - self.hv_fixed

    def relative(self, hv: float) -> float:
        """``hv / hv_fixed - 1``."""
        return hv / self.hv_fixed - 1.0 if self.hv_fixed > 0 else float("nan")

    @staticmethod
    def interval(differences: np.ndarray, level: float = 0.95) -> tuple[float, float]:
        """Percentile interval of ``differences`` holding ``level`` of the draws."""
        if not 0.0 < level < 1.0:
            raise ValueError(f"level must lie in (0, 1), got {level!r}")
        lo, hi = np.quantile(differences, [(1.0 - level) / 2.0, (1.0 + level) / 2.0])
        return float(lo), float(hi)


def _outcomes(rows: Sequence[Mapping[str, Any]]) -> dict[tuple, tuple]:
    """(strategy, circuit, rho, seed) -> (success, overtakes, simulated time) of ``rows``."""
    return {(r["strategy"], str(r["track"]), float(r["rho"]), int(r["seed"])):
            (bool(int(float(r["success"]))), int(float(r["overtakes"])), float(r["sim_time"])) for r in rows}


def _check_files(files: Mapping[str, Sequence[Mapping[str, Any]]]) -> tuple[list[str], list[str], list[str]]:
    """The fixed strategies, the policy strategies and the policy id of each file; ``ValueError`` where the files
    break the contract of the module docstring."""
    names = list(files)
    if len(names) < 2:
        raise ValueError("a recipe's front needs the files of at least two training seeds")
    fixed_rows, policy_names, ids, hashes = {}, {}, [], set()
    for name in names:
        rows = files[name]
        if not rows:
            raise ValueError(f"{name} has no episode rows")
        strategies = list(dict.fromkeys(r["strategy"] for r in rows))
        fixed_rows[name] = _outcomes([r for r in rows if _family_of(r["strategy"]) == "fixed"])
        policy_names[name] = [s for s in strategies if _family_of(s) == "policy"]
        if not fixed_rows[name] or not policy_names[name]:
            raise ValueError(f"{name} needs fixed-gamma rows and rows of a preference-conditioned policy")
        pid = {str(r.get("policy_id", "")) for r in rows if _family_of(r["strategy"]) == "policy"}
        if len(pid) != 1 or "" in pid:
            raise ValueError(f"{name}: its policy rows must carry one policy_id, found {sorted(pid)}")
        ids.append(pid.pop())
        hashes |= {str(r.get("config_hash", "")) for r in rows}
    first = names[0]
    for name in names[1:]:
        if fixed_rows[name] != fixed_rows[first]:
            diff = sorted(set(fixed_rows[name].items()) ^ set(fixed_rows[first].items()))[:2]
            raise ValueError(f"the fixed-gamma rows of {name} differ from those of {first} (e.g. {diff}): the seeds' "
                             "fronts must be measured against the same fixed rows")
        if sorted(policy_names[name]) != sorted(policy_names[first]):
            raise ValueError(f"{name} holds the preferences {policy_names[name]}, {first} {policy_names[first]}")
    if len(set(ids)) != len(ids):
        raise ValueError(f"one policy is in two files (policy ids {ids}): give one file per training seed")
    if len(hashes) != 1 or "" in hashes:
        raise ValueError(f"the rows must carry one configuration hash, found {sorted(hashes)}")
    fixed = list(dict.fromkeys(r["strategy"] for r in files[first] if _family_of(r["strategy"]) == "fixed"))
    return fixed, policy_names[first], ids


def training_seed_fronts(files: Mapping[str, Sequence[Mapping[str, Any]]], resamples: int = 2000,
                         seed: int = 0) -> TrainingSeedFronts:
    """The fronts of the recipe whose k training seeds' Pareto rows ``files`` holds (file name -> its rows, e.g.
    :func:`~.results.read_seed_sets`), with the two bootstraps of the module docstring. Raises ``ValueError`` as it
    says, and for ``resamples`` < 100."""
    if int(resamples) != resamples or resamples < 100:
        raise ValueError(f"resamples must be an integer >= 100, got {resamples!r}")
    fixed, prefs, ids = _check_files(files)
    names = list(files)
    k = len(names)
    rows = [dict(r) for r in files[names[0]] if r["strategy"] in fixed]
    for i, name in enumerate(names):
        rows += [{**r, "strategy": f"{r['strategy']}{_SEP}{i}"} for r in files[name] if r["strategy"] in prefs]
    seeded = [[f"{p}{_SEP}{i}" for p in prefs] for i in range(k)]
    table, cells = _episode_table(rows, fixed + [s for row in seeded for s in row])
    by_name = {}
    for r in rows:
        by_name.setdefault(r["strategy"], []).append(r)
    fixed_pts = tuple(_point(s, "fixed", by_name[s], None) for s in fixed)
    per_seed = tuple(tuple(_point(p, "policy", by_name[f"{p}{_SEP}{i}"], _preference_of(p)) for p in prefs)
                     for i in range(k))
    pooled = tuple(_point(p, "policy", [r for i in range(k) for r in by_name[f"{p}{_SEP}{i}"]], _preference_of(p))
                   for p in prefs)
    gamma = tuple(tuple(float(np.mean([float(r["mean_gamma"]) for r in by_name[f"{p}{_SEP}{i}"]])) for p in prefs)
                  for i in range(k))
    values = lambda pts: np.array([(p.success, p.overtakes_per_hour) for p in pts])  # noqa: E731
    hv_fixed, hv_pooled = hypervolume(values(fixed_pts)), hypervolume(values(pooled))
    hv_seeds = tuple(hypervolume(values(pts)) for pts in per_seed)

    rng = np.random.default_rng(seed)
    n = int(resamples)
    counts, n_cells = _draw_episodes(cells, n, rng)
    picks = np.zeros((n, k))  # how often each draw takes each training seed
    np.add.at(picks, (np.arange(n)[:, None], rng.integers(0, k, size=(n, k))), 1.0)
    points = {s: _points(counts, t) for s, t in table.items()}  # (draws, 2) per strategy
    hv_draws = np.array([[hypervolume(np.array([points[s][b] for s in strategies])) for b in range(n)]
                         for strategies in [fixed] + seeded])
    seed_diffs = hv_draws[1:] - hv_draws[0]  # (k, draws)
    diffs = np.stack([seed_diffs.mean(axis=0), (picks.T * seed_diffs).sum(axis=0) / k])
    return TrainingSeedFronts(tuple(names), tuple(ids), fixed_pts, per_seed, pooled, gamma, hv_fixed, hv_seeds,
                              hv_pooled, len(cells), n_cells, n, int(seed), diffs[0], diffs[1])


def training_seeds_markdown(result: TrainingSeedFronts, level: float = 0.95) -> str:
    """A Markdown report of ``result``."""
    r = result
    pct = lambda x: 100.0 * x / r.hv_fixed if r.hv_fixed > 0 else float("nan")  # noqa: E731
    rel_seeds = [100.0 * r.relative(h) for h in r.hv_seeds]
    lines = ["# A recipe's front over its training seeds, against the fixed gammas on the same episodes", "",
             f"{len(r.sources)} training seeds, one file each: "
             + ", ".join(f"{s} (policy {p})" for s, p in zip(r.sources, r.policy_ids))
             + f". {r.episodes} episodes per strategy and file in {r.cells} (circuit, rho) cells.", "",
             "| front | hypervolume [% x 1/h] | against the fixed gammas' |", "|---|---:|---:|",
             f"| fixed gammas | {r.hv_fixed:,.0f} | |"]
    lines += [f"| seed file {i + 1} | {h:,.0f} | {x:+.1f} % |" for i, (h, x) in enumerate(zip(r.hv_seeds, rel_seeds))]
    lines += [f"| **the recipe: mean over the seeds** | **{np.mean(r.hv_seeds):,.0f}** | **{pct(r.difference):+.1f} "
              f"%** (sd {np.std(rel_seeds, ddof=1):.1f} points) |",
              f"| pooled front (descriptive: {len(r.sources)} x the episodes per point) | {r.hv_pooled:,.0f} | "
              f"{100.0 * r.relative(r.hv_pooled):+.1f} % |", "",
              f"| paired bootstrap of the recipe's difference ({r.resamples} draws, generator seed {r.seed}) | "
              f"{100 * level:g} % interval | share of draws >= 0 |", "|---|---:|---:|"]
    for label, d in (("the episodes drawn, the policies kept", r.diff_episodes),
                     ("the training seeds and the episodes drawn", r.diff_seeds_episodes)):
        lo, hi = r.interval(d, level)
        lines.append(f"| {label} | {pct(lo):+.1f} to {pct(hi):+.1f} % | {100.0 * np.mean(d >= 0.0):.1f} % |")
    lines += ["", "Fixed gammas (success [%], overtakes/h): " + "; ".join(
        f"{p.name} {p.success:.1f}, {p.overtakes_per_hour:.0f}" for p in r.fixed) + ".", "",
        "| preference | " + " | ".join(f"seed file {i + 1}: success [%], overtakes/h, mean gamma"
                                       for i in range(len(r.sources))) + " | pooled: success [%], overtakes/h |",
        "|---|" + "---:|" * (len(r.sources) + 1)]
    for j, p in enumerate(r.pooled):
        seeds = [f"{s[j].success:.1f}, {s[j].overtakes_per_hour:.0f}, {g[j]:.3f}"
                 for s, g in zip(r.per_seed, r.mean_gamma)]
        lines.append(f"| {p.name} | " + " | ".join(seeds) + f" | {p.success:.1f}, {p.overtakes_per_hour:.0f} |")
    lines += ["", "Each seed's front rests on as many episodes per point as the fixed gammas', so their hypervolumes "
              "carry the same noise; the pooled front's points rest on more and keep fewer lucky ones. The second "
              "bootstrap covers training luck only as far as these seeds show it.", ""]
    return "\n".join(lines)
