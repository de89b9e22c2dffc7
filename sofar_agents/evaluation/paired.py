"""Is one strategy's success rate really higher than another's? Paired tests on seeded episodes.

Every strategy of a Table I run drives the same seeded episodes (same circuit, pace ratio rho and
seed), so two strategies are compared episode by episode, not as two independent samples. Only the
*discordant* episodes carry information: ``a_only`` (strategy A succeeds, B fails) and ``b_only``.
For two strategies with the same success probability, ``a_only`` is Binomial(a_only + b_only, 1/2);
the two-sided exact test of that (McNemar's exact test) gives the p-value. The difference of the
success rates is ``(a_only - b_only) / n`` over ``n`` paired episodes, with the normal-approximation
standard error of a paired difference of proportions,
``sqrt(a_only + b_only - (a_only - b_only)**2 / n) / n``.

Episodes are paired within a seed set (one ``table1_episodes.csv``) by (circuit, rho, seed, with
or without the MIQP layer); several seed sets are pooled by keeping their episodes apart.
Episodes that only one of the two strategies has are left out and counted.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from scipy.stats import binomtest

__all__ = ["PairedComparison", "paired_comparison", "compare_to", "format_paired", "label_by_stack"]


@dataclass(frozen=True)
class PairedComparison:
    """Strategy ``a`` against strategy ``b`` on the episodes both ran (rates in [0, 1])."""

    a: str
    b: str
    n: int
    """Paired episodes."""
    success_a: float
    success_b: float
    a_only: int
    """Episodes that ``a`` wins and ``b`` does not."""
    b_only: int
    unpaired: int
    """Episodes of either strategy without a partner (left out)."""

    @property
    def difference(self) -> float:
        """Success of ``a`` minus success of ``b`` over the paired episodes."""
        return (self.a_only - self.b_only) / self.n if self.n else float("nan")

    @property
    def standard_error(self) -> float:
        """Standard error of :attr:`difference` (normal approximation for paired proportions)."""
        if not self.n:
            return float("nan")
        d = self.a_only - self.b_only
        return math.sqrt(max(self.a_only + self.b_only - d * d / self.n, 0.0)) / self.n

    @property
    def p_value(self) -> float:
        """Two-sided exact McNemar p-value (1.0 without discordant episodes)."""
        k = self.a_only + self.b_only
        return 1.0 if k == 0 else float(binomtest(self.a_only, k, 0.5).pvalue)


def label_by_stack(sets: Mapping[str, Iterable[Mapping[str, Any]]]) -> dict[str, list[dict[str, Any]]]:
    """The seed sets with each row's strategy named ``<stack>:<strategy>`` (``stack`` column, ``"sofar-1"``
    when empty: :data:`~sofar_agents.evaluation.protocol.LEGACY_STACK`), so that one strategy run with two
    controller presets on the same episodes can be compared
    (``"sofar-recover:gamma=0.05"`` against ``"sofar:gamma=0.05"``). The rows given are not changed."""
    from sofar_agents.evaluation.protocol import LEGACY_STACK

    return {name: [{**r, "strategy": f"{r.get('stack') or LEGACY_STACK}:{r['strategy']}"} for r in rows]
            for name, rows in sets.items()}


def _episode_key(set_name: str, r: Mapping[str, Any]) -> tuple:
    return (set_name, str(r["track"]), round(float(r["rho"]), 6), int(r["seed"]), bool(r.get("use_miqp", True)))


def _outcomes(sets: Mapping[str, Sequence[Mapping[str, Any]]], strategy: str) -> dict[tuple, bool]:
    """Success per episode of ``strategy`` over the seed sets. ``ValueError`` when its rows come from two
    configurations (two ``config_hash`` values, or rows with one and rows without: files written before the
    column), from two policies in one set, or hold an episode twice."""
    from sofar_agents.evaluation.configs import check_one_config

    check_one_config((r for rows in sets.values() for r in rows if str(r["strategy"]) == strategy),
                     lambda r: strategy, "paired comparison")
    out: dict[tuple, bool] = {}
    for name, rows in sets.items():
        mine = [r for r in rows if str(r["strategy"]) == strategy]
        policies = {str(r.get("policy_id", "") or "") for r in mine}
        if len(policies) > 1:
            raise ValueError(f"strategy {strategy!r} mixes {len(policies)} policies in seed set {name!r}; "
                             "keep one policy per CSV")
        for r in mine:
            key = _episode_key(name, r)
            if key in out:
                raise ValueError(f"strategy {strategy!r} has episode {key[1:]} twice in seed set {name!r}")
            out[key] = bool(r["success"])
    return out


def paired_comparison(sets: Mapping[str, Iterable[Mapping[str, Any]]], a: str, b: str) -> PairedComparison:
    """Strategy ``a`` against ``b`` (names as in the CSV's ``strategy`` column, e.g. ``"adaptive"``,
    ``"gamma=0.05"``) over the seed sets ``sets`` (name -> episode rows).

    Raises ``ValueError`` if ``a == b``, if either strategy has no episode, or if the two share none.
    """
    if a == b:
        raise ValueError(f"compare two different strategies, got {a!r} twice")
    sets = {name: list(rows) for name, rows in sets.items()}
    oa, ob = _outcomes(sets, a), _outcomes(sets, b)
    for name, o in ((a, oa), (b, ob)):
        if not o:
            known = sorted({str(r["strategy"]) for rows in sets.values() for r in rows})
            raise ValueError(f"no episodes of strategy {name!r}; the CSVs have {known}")
    common = oa.keys() & ob.keys()
    if not common:
        raise ValueError(f"strategies {a!r} and {b!r} share no episode (different seeds or circuits)")
    a_only = sum(oa[k] and not ob[k] for k in common)
    b_only = sum(ob[k] and not oa[k] for k in common)
    return PairedComparison(
        a=a, b=b, n=len(common),
        success_a=sum(oa[k] for k in common) / len(common),
        success_b=sum(ob[k] for k in common) / len(common),
        a_only=a_only, b_only=b_only,
        unpaired=len(oa.keys() ^ ob.keys()),
    )


def compare_to(sets: Mapping[str, Iterable[Mapping[str, Any]]], a: str,
               others: Sequence[str] | None = None) -> list[PairedComparison]:
    """``a`` against each of ``others`` (default: every other strategy of the sets, in sorted order)."""
    sets = {name: list(rows) for name, rows in sets.items()}
    if others is None:
        others = sorted({str(r["strategy"]) for rows in sets.values() for r in rows} - {a})
    return [paired_comparison(sets, a, b) for b in others]


def format_paired(rows: Sequence[PairedComparison]) -> str:
    """A Markdown table of paired comparisons (rates and differences in percentage points)."""
    lines = [
        "| A | B | paired episodes | A [%] | B [%] | A − B [points] | ± s.e. | A only | B only | p (exact McNemar) |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for c in rows:
        lines.append(
            f"| {c.a} | {c.b} | {c.n} | {100 * c.success_a:.1f} | {100 * c.success_b:.1f} "
            f"| {100 * c.difference:+.1f} | {100 * c.standard_error:.1f} | {c.a_only} | {c.b_only} | {c.p_value:.3g} |"
        )
    return "\n".join(lines) + "\n"
