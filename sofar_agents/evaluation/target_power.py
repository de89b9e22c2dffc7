"""How often a fixed gamma itself would meet a "within d points of the best fixed gamma" target on a fresh seed set.

The safety-first target of a preference-conditioned policy compares its success with the best of the six fixed
gammas on the same episodes. The best of six noisy rates is biased upwards (it is a maximum), so before reading a
miss as the policy's fault it helps to know how often a strategy that *is* one of the fixed gammas would meet the
target on a set of the same size. :func:`target_power` estimates that by resampling episodes, with their
outcomes under every fixed gamma kept together (the episodes are paired), from the pooled episodes of one or more
seed sets: per fixed gamma, the probability that its success on ``episodes`` resampled episodes is within
``margin`` of the best fixed gamma's on the same episodes, and its mean shortfall.
No episode is run; the rows are those of ``eval/table.py`` or ``eval/pareto.py``.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from .paired import _outcomes

__all__ = ["TargetPower", "target_power", "format_target_power"]


@dataclass(frozen=True)
class TargetPower:
    """One fixed gamma's chance to meet the target (see the module docstring)."""

    strategy: str
    pooled_success: float
    """Its success over the pooled episodes."""
    probability: float
    """Share of the resampled sets on which its success is within the margin of the best fixed gamma's."""
    mean_shortfall: float
    """Mean of (its success - the best fixed gamma's) over the resampled sets (<= 0)."""
    shortfall_p10: float
    """10th percentile of that difference."""


def target_power(sets: Mapping[str, Iterable[Mapping[str, Any]]], episodes: int = 40, margin: float = 0.02,
                 resamples: int = 20000, seed: int = 0) -> tuple[int, list[TargetPower]]:
    """``(pooled episodes, one TargetPower per fixed gamma)`` over the episodes that every fixed gamma (strategies
    named ``gamma=...``) of the seed sets ``sets`` (name -> episode rows) ran. Raises ``ValueError`` with fewer than
    two fixed gammas, without an episode they share, or for ``episodes`` < 1, ``margin`` < 0 or ``resamples`` < 1."""
    if episodes < 1 or resamples < 1 or not margin >= 0.0:
        raise ValueError(f"episodes and resamples must be >= 1 and margin >= 0, got {episodes}, {resamples}, "
                         f"{margin}")
    sets = {name: list(rows) for name, rows in sets.items()}
    strategies = {str(r["strategy"]) for rows in sets.values() for r in rows}
    names = sorted((s for s in strategies if s.startswith("gamma=")), key=lambda s: float(s.partition("=")[2]))
    if len(names) < 2:
        raise ValueError(f"the target compares with the best of several fixed gammas; the rows have {names}")
    outcomes = [_outcomes(sets, s) for s in names]
    common = sorted(set.intersection(*(set(o) for o in outcomes)))
    if not common:
        raise ValueError(f"the fixed gammas {names} share no episode")
    success = np.array([[o[k] for o in outcomes] for k in common], dtype=float)  # (episodes, gammas)
    rng = np.random.default_rng(seed)
    rates = success[rng.integers(0, len(common), size=(resamples, episodes))].mean(axis=1)  # (resamples, gammas)
    diff = rates - rates.max(axis=1, keepdims=True)
    tol = 1e-9  # rates are multiples of 1 / episodes: "within 2 points" includes exactly 2 points
    rows = [TargetPower(name, float(success[:, j].mean()), float(np.mean(diff[:, j] >= -margin - tol)),
                        float(diff[:, j].mean()), float(np.quantile(diff[:, j], 0.1)))
            for j, name in enumerate(names)]
    return len(common), rows


def format_target_power(n_pooled: int, rows: list[TargetPower], episodes: int, margin: float, resamples: int) -> str:
    """Markdown table of :func:`target_power`."""
    lines = [f"Pooled episodes that every fixed gamma ran: {n_pooled}; {resamples} resampled sets of {episodes} "
             f"episodes; target: success within {100 * margin:g} points of the best fixed gamma on the same set.",
             "",
             "| strategy | pooled success | P(target met) | mean shortfall (points) | 10th percentile (points) |",
             "|---|---:|---:|---:|---:|"]
    for r in rows:
        lines.append(f"| {r.strategy} | {100 * r.pooled_success:.1f} % | {r.probability:.2f} | "
                     f"{100 * r.mean_shortfall:.1f} | {100 * r.shortfall_p10:.1f} |")
    return "\n".join(lines) + "\n"
