"""How much could an adaptive gamma gain over the best fixed one? Oracles on fixed-gamma episodes.

Before training a policy to choose gamma, a Table I of fixed gammas already says how much
a choice that depends on the *conditions* of an episode (the circuit, the opponents' pace
ratio rho) could gain, and whether that gain survives a second seed set. For each seed set
``S`` (the fixed-gamma rows of one ``table1_episodes.csv``, Table I protocol):

- **best fixed**: the highest aggregate success of one gamma on ``S``;
- **condition oracle, in sample**: per condition (circuit, rho) the best gamma *on S
  itself*, averaged over the conditions. It picks the luckiest gamma of every cell, so it
  is an upper bound that includes the noise;
- **condition oracle, cross-set**: per condition the gamma that was best on the *other*
  seed sets, scored on ``S``. This is an honest estimate of what knowing the circuit and rho
  is worth: if it does not beat the best fixed gamma, the per-condition differences of the
  table are noise;
- **circuit oracle, cross-set**: the same with one gamma per circuit (per-track tuning);
- **episode oracle**: the share of episodes that at least one fixed gamma wins. It bounds
  any strategy that only picks one gamma per episode; its distance to the shares that every
  gamma wins shows how much a race's outcome turns on small differences.

:func:`outcome_flips` adds the other half of the picture: for every pair of gammas, the share of
paired episodes whose outcome (success or not) differs. If two nearly equal gammas (0.05 and 0.06)
flip about as many outcomes as two distant ones, a race's outcome turns on small perturbations
(chaos), which no choice of gamma can predict.

A gain that only a within-episode choice can reach (a gamma that changes with the state
during a race) is not measured here; it is what the per-step policy of PASTA is for.

Only the gammas a set was run with are candidates for it. Ties between gammas are broken towards the gamma with the higher aggregate success on the
picking sets, then towards the smaller gamma, so every oracle is deterministic.
"""

from __future__ import annotations

import math
from collections import defaultdict
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

__all__ = ["HeadroomRow", "fixed_gamma_rows", "headroom", "format_headroom", "outcome_flips", "format_flips"]

_Condition = tuple[str, float]


@dataclass(frozen=True)
class HeadroomRow:
    """The oracles of one seed set (success rates in [0, 1])."""

    name: str
    """Label of the seed set (e.g. the CSV's folder)."""
    episodes: int
    """Episodes per gamma in this set."""
    best_fixed_gamma: float
    best_fixed: float
    condition_oracle_in_sample: float
    condition_oracle_cross: float | None
    """None with a single seed set."""
    circuit_oracle_cross: float | None
    episode_oracle: float
    all_gammas_win: float
    """Share of episodes that every fixed gamma wins."""

    @property
    def standard_error(self) -> float:
        """Binomial standard error of the best fixed gamma's rate over ``episodes``."""
        p = self.best_fixed
        return math.sqrt(max(p * (1.0 - p), 0.0) / self.episodes) if self.episodes else float("nan")


def _gamma_of(strategy: str) -> float | None:
    if not strategy.startswith("gamma="):
        return None
    return float(strategy.split("=", 1)[1])


def fixed_gamma_rows(rows: Iterable[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """The Table I rows of fixed gammas (the MIQP on), each with its ``gamma`` as a float."""
    out = []
    for r in rows:
        g = _gamma_of(str(r["strategy"]))
        if g is not None and r.get("use_miqp", True):
            out.append({**r, "gamma": g})
    return out


def _success_table(rows: Sequence[Mapping[str, Any]], key) -> dict[Any, dict[float, list[float]]]:
    table: dict[Any, dict[float, list[float]]] = defaultdict(lambda: defaultdict(list))
    for r in rows:
        table[key(r)][r["gamma"]].append(float(bool(r["success"])))
    return table


def _mean(xs: Sequence[float]) -> float:
    return sum(xs) / len(xs)


def _pick(cell: Mapping[float, Sequence[float]], overall: Mapping[float, float]) -> float:
    """The gamma with the best success in ``cell``; ties by ``overall`` success, then the smaller gamma."""
    return min(cell, key=lambda g: (-_mean(cell[g]), -overall.get(g, 0.0), g))


def _overall(rows: Sequence[Mapping[str, Any]]) -> dict[float, float]:
    by_gamma: dict[float, list[float]] = defaultdict(list)
    for r in rows:
        by_gamma[r["gamma"]].append(float(bool(r["success"])))
    return {g: _mean(v) for g, v in by_gamma.items()}


def _cross(rows: Sequence[Mapping[str, Any]], others: Sequence[Mapping[str, Any]], key) -> float:
    """Success on ``rows`` of the gamma picked per ``key`` on ``others``, averaged over the cells of ``rows``."""
    here = _success_table(rows, key)
    there = _success_table(others, key)
    gammas = {r["gamma"] for r in rows}
    overall = {g: s for g, s in _overall(others).items() if g in gammas}
    if not overall:
        raise ValueError("the seed sets share no fixed gamma")
    scores = []
    for cell_key, cell in here.items():
        picks = {g: v for g, v in there.get(cell_key, {}).items() if g in gammas}
        # a cell the other sets lack: the best fixed gamma of the other sets
        g = _pick(picks, overall) if picks else min(overall, key=lambda x: (-overall[x], x))
        scores.append(_mean(cell[g]))
    return _mean(scores)


def _condition(r: Mapping[str, Any]) -> _Condition:
    return (str(r["track"]), round(float(r["rho"]), 6))


def _circuit(r: Mapping[str, Any]) -> str:
    return str(r["track"])


def _episode(r: Mapping[str, Any]) -> tuple:
    return (str(r["track"]), round(float(r["rho"]), 6), int(r["seed"]))


def headroom(sets: Mapping[str, Iterable[Mapping[str, Any]]]) -> list[HeadroomRow]:
    """The oracles of every seed set in ``sets`` (name -> episode rows, as read by ``read_episode_csv``).

    Raises ``ValueError`` if a set has no fixed-gamma rows, or if its gammas do not all have
    the same episodes (the table is incomplete).
    """
    fixed = {name: fixed_gamma_rows(rows) for name, rows in sets.items()}
    for name, rows in fixed.items():
        if not rows:
            raise ValueError(f"seed set {name!r} has no fixed-gamma rows")
        episodes = _success_table(rows, _episode)
        gammas = {r["gamma"] for r in rows}
        incomplete = [k for k, cell in episodes.items() if set(cell) != gammas]
        if incomplete:
            raise ValueError(f"seed set {name!r}: {len(incomplete)} episodes lack some gamma, e.g. {incomplete[0]}; "
                             "complete the table first")
    out = []
    for name, rows in fixed.items():
        others = [r for other, rs in fixed.items() if other != name for r in rs]
        overall = _overall(rows)
        best_gamma = min(overall, key=lambda g: (-overall[g], g))
        conditions = _success_table(rows, _condition)
        episodes = _success_table(rows, _episode)
        wins = [max(_mean(v) for v in cell.values()) for cell in episodes.values()]
        every = [min(_mean(v) for v in cell.values()) for cell in episodes.values()]
        out.append(HeadroomRow(
            name=name,
            episodes=len(episodes),
            best_fixed_gamma=best_gamma,
            best_fixed=overall[best_gamma],
            condition_oracle_in_sample=_mean([max(_mean(v) for v in cell.values()) for cell in conditions.values()]),
            condition_oracle_cross=_cross(rows, others, _condition) if others else None,
            circuit_oracle_cross=_cross(rows, others, _circuit) if others else None,
            episode_oracle=_mean(wins),
            all_gammas_win=_mean(every),
        ))
    return out


def _pct(x: float | None) -> str:
    return "-" if x is None else f"{100.0 * x:.1f}"


def format_headroom(rows: Sequence[HeadroomRow]) -> str:
    """A Markdown table of :func:`headroom`'s rows (success in %)."""
    lines = [
        "| seed set | episodes / γ | best fixed γ | best fixed [%] | ± s.e. | condition oracle, in sample [%] "
        "| condition oracle, cross-set [%] | circuit oracle, cross-set [%] | episode oracle [%] | every γ wins [%] |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        lines.append(
            f"| {r.name} | {r.episodes} | {r.best_fixed_gamma:.2f} | {_pct(r.best_fixed)} | {100 * r.standard_error:.1f} "
            f"| {_pct(r.condition_oracle_in_sample)} | {_pct(r.condition_oracle_cross)} "
            f"| {_pct(r.circuit_oracle_cross)} | {_pct(r.episode_oracle)} | {_pct(r.all_gammas_win)} |"
        )
    return "\n".join(lines) + "\n"


def outcome_flips(rows: Iterable[Mapping[str, Any]]) -> dict[tuple[float, float], tuple[float, int]]:
    """For every pair of fixed gammas (g1 < g2): (share of their common episodes with different outcomes, count)."""
    episodes = _success_table(fixed_gamma_rows(rows), _episode)
    gammas = sorted({g for cell in episodes.values() for g in cell})
    out = {}
    for i, g1 in enumerate(gammas):
        for g2 in gammas[i + 1:]:
            pairs = [(cell[g1][0], cell[g2][0]) for cell in episodes.values() if g1 in cell and g2 in cell]
            if pairs:
                out[(g1, g2)] = (sum(a != b for a, b in pairs) / len(pairs), len(pairs))
    return out


def format_flips(flips: Mapping[tuple[float, float], tuple[float, int]]) -> str:
    """A Markdown matrix of :func:`outcome_flips` (per cent of paired episodes whose outcome differs)."""
    gammas = sorted({g for pair in flips for g in pair})
    lines = ["| γ | " + " | ".join(f"{g:g}" for g in gammas) + " |", "|---|" + "---:|" * len(gammas)]
    for g1 in gammas:
        cells = []
        for g2 in gammas:
            key = (min(g1, g2), max(g1, g2))
            cells.append("" if g1 == g2 or key not in flips else f"{100.0 * flips[key][0]:.0f}")
        lines.append(f"| {g1:g} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"
