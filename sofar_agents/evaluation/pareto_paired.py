"""Paired tests of a Pareto sweep's points: each policy point against the fixed gammas it should be read against.

A point of a preference-conditioned policy (or of another baseline) is compared, on the same seeded episodes,
with the fixed gamma nearest to its mean gamma and with the best fixed gamma (highest success): success by
the exact McNemar test (:mod:`sofar_agents.evaluation.paired`), and the overtaking rate (overtakes per
simulated hour, per episode) by the Wilcoxon signed-rank test. No episode is run.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from sofar_agents.evaluation.paired import PairedComparison, format_paired, paired_comparison

__all__ = ["RateComparison", "compare_points", "format_pareto_paired", "pareto_pairs", "rate_comparison"]


@dataclass(frozen=True)
class RateComparison:
    """Overtakes per simulated hour of A and B on their paired episodes."""

    a: str
    b: str
    n: int
    rate_a: float
    """Mean per-episode rate of A [1/h]."""
    rate_b: float
    median_difference: float
    """Median of the per-episode differences A - B [1/h]."""
    p_value: float
    """Two-sided Wilcoxon signed-rank p (1 when every difference is zero, nan without pairs)."""


def _key(r: Mapping[str, Any]) -> tuple:
    return (str(r["track"]), round(float(r["rho"]), 6), int(r["seed"]), bool(r.get("use_miqp", True)))


def _rate(r: Mapping[str, Any]) -> float:
    t = float(r["sim_time"])
    return int(r["overtakes"]) / t * 3600.0 if t > 0 else 0.0


def rate_comparison(rows: Sequence[Mapping[str, Any]], a: str, b: str) -> RateComparison:
    """Paired per-episode overtaking rates of strategies ``a`` and ``b`` in one seed set's ``rows``."""
    from scipy.stats import wilcoxon

    ra = {_key(r): _rate(r) for r in rows if r["strategy"] == a}
    rb = {_key(r): _rate(r) for r in rows if r["strategy"] == b}
    keys = sorted(set(ra) & set(rb))
    if not keys:
        return RateComparison(a, b, 0, math.nan, math.nan, math.nan, math.nan)
    d = np.array([ra[k] - rb[k] for k in keys])
    p = float(wilcoxon(d).pvalue) if np.any(d != 0) else 1.0
    return RateComparison(a, b, len(keys), float(np.mean([ra[k] for k in keys])),
                          float(np.mean([rb[k] for k in keys])), float(np.median(d)), p)


def pareto_pairs(rows: Sequence[Mapping[str, Any]], extra: Sequence[str] = ()) -> list[tuple[str, float, list[str]]]:
    """``(point, its mean gamma, [nearest fixed gamma, best fixed gamma, *extra])`` for every non-fixed strategy.

    Fixed strategies are those named ``gamma=<value>``; the best is the one with the highest success
    (the first listed among ties); the nearest is by ``|value - mean gamma of the point's episodes|``;
    ``extra`` names more strategies every point is compared with (each listed once). ``ValueError`` when
    ``rows`` hold no fixed gamma or an ``extra`` strategy is not in them.
    """
    names = list(dict.fromkeys(str(r["strategy"]) for r in rows))
    fixed = [s for s in names if s.startswith("gamma=")]
    if not fixed:
        raise ValueError("the rows hold no fixed gamma (strategy gamma=<value>) to compare with")
    missing = [e for e in extra if e not in names]
    if missing:
        raise ValueError(f"no episodes of {missing}; the rows have {names}")
    success = {s: np.mean([str(r["success"]).lower() in ("true", "1") for r in rows if r["strategy"] == s])
               for s in fixed}
    best = max(fixed, key=lambda s: success[s])
    out = []
    for s in names:
        if s in fixed:
            continue
        mean_gamma = float(np.mean([float(r["mean_gamma"]) for r in rows if r["strategy"] == s]))
        nearest = min(fixed, key=lambda g: abs(float(g.split("=", 1)[1]) - mean_gamma))
        out.append((s, mean_gamma, list(dict.fromkeys([nearest, best, *[e for e in extra if e != s]]))))
    return out


def compare_points(rows: Sequence[Mapping[str, Any]], set_name: str = "set", extra: Sequence[str] = ()
                   ) -> tuple[list[tuple[str, float, list[str]]], list[PairedComparison], list[RateComparison]]:
    """The pairs of :func:`pareto_pairs` with their success and overtaking-rate comparisons."""
    pairs = pareto_pairs(rows, extra)
    sets = {set_name: list(rows)}
    success = [paired_comparison(sets, s, g) for s, _, gs in pairs for g in gs]
    rates = [rate_comparison(rows, s, g) for s, _, gs in pairs for g in gs]
    return pairs, success, rates


def format_pareto_paired(rows: Sequence[Mapping[str, Any]], set_name: str = "set", extra: Sequence[str] = ()) -> str:
    """Markdown: the points' mean gammas, the success tests, then the overtaking-rate tests."""
    pairs, success, rates = compare_points(rows, set_name, extra)
    lines = ["| point | mean gamma | compared with |", "|---|---:|---|"]
    lines += [f"| {s} | {g:.3f} | {', '.join(gs)} |" for s, g, gs in pairs]
    text = "\n".join(lines) + "\n\n**Success** (exact McNemar):\n\n" + format_paired(success)
    lines = ["| A | B | paired episodes | A [1/h] | B [1/h] | median A − B [1/h] | p (Wilcoxon) |",
             "|---|---|---:|---:|---:|---:|---:|"]
    lines += [f"| {c.a} | {c.b} | {c.n} | {c.rate_a:.1f} | {c.rate_b:.1f} | {c.median_difference:+.1f} | "
              f"{c.p_value:.3g} |" for c in rates]
    return text + "\n**Overtakes per hour** (per episode, Wilcoxon signed-rank):\n\n" + "\n".join(lines) + "\n"
