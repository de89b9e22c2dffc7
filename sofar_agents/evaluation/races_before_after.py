"""Two controllers on the same seeded multi-car races: the before and after of a change, race by race.

:func:`races_before_after` pairs the rows of two per-race CSVs of the multi-agent table
(``multi_agent_races.csv``, :mod:`sofar_agents.evaluation.multi_agent`) made with two controllers on the same
races: same circuit, strategy, seed, cars, duration and world. Per strategy and for all of them together it counts
the cars that reached the duration (success per car), the races with a collision (with the exact McNemar test of
:class:`~sofar_agents.evaluation.paired.PairedComparison` on the races that have one on one side only),
off-track and stalled cars, overtakes per race, and the lateral plans in force that were the passing planner's
fallback (``miqp_failures``; unknown on a side whose CSV predates the column). Rows of one side must come from one
configuration (one ``config_hash``).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from .before_after import paired_rows
from .paired import PairedComparison

__all__ = ["RaceOutcomes", "RacesBeforeAfter", "races_before_after", "format_races_before_after"]

ALL = "all strategies"
"""The label of the line that pools every strategy."""


@dataclass(frozen=True)
class RaceOutcomes:
    """Counts of one side over the paired races."""

    cars: int
    success: int
    collision_races: int
    off_track: int
    stalled: int
    overtakes: int
    fallbacks: int | None
    """Plans in force that were the planner's fallback, summed (None: a race of this side did not record them)."""


@dataclass(frozen=True)
class RacesBeforeAfter:
    """One strategy before and after: the paired test of races with a collision, both sides' outcomes."""

    strategy: str
    test: PairedComparison
    """``a`` = after, ``b`` = before; a "success" is a race without a collision."""
    before: RaceOutcomes
    after: RaceOutcomes


def _key(r: Mapping[str, Any]) -> tuple:
    return (str(r["track"]), int(r["seed"]), int(r["cars"]), round(float(r["duration"]), 6), str(r["scenario"]),
            str(r.get("opponents", "0") or "0"), str(r["strategy"]))


def _outcomes(rows: Sequence[Mapping[str, Any]]) -> RaceOutcomes:
    fallbacks = [int(r.get("miqp_failures", -1) or -1) for r in rows]
    return RaceOutcomes(cars=sum(int(r["cars"]) for r in rows), success=sum(int(r["success"]) for r in rows),
                        collision_races=sum(int(r["collided"]) > 0 for r in rows),
                        off_track=sum(int(r["off_track"]) for r in rows), stalled=sum(int(r["stalled"]) for r in rows),
                        overtakes=sum(int(r["overtakes"]) for r in rows),
                        fallbacks=None if any(f < 0 for f in fallbacks) else sum(fallbacks))


def _line(name: str, pairs: Sequence[tuple[Mapping[str, Any], Mapping[str, Any]]]) -> RacesBeforeAfter:
    clean = lambda r: int(r["collided"]) == 0  # noqa: E731
    n = len(pairs)
    test = PairedComparison(a="after", b="before", n=n, success_a=sum(clean(a) for _, a in pairs) / n,
                            success_b=sum(clean(b) for b, _ in pairs) / n,
                            a_only=sum(1 for b, a in pairs if clean(a) and not clean(b)),
                            b_only=sum(1 for b, a in pairs if clean(b) and not clean(a)), unpaired=0)
    return RacesBeforeAfter(name, test, _outcomes([b for b, _ in pairs]), _outcomes([a for _, a in pairs]))


def races_before_after(before: Iterable[Mapping[str, Any]],
                       after: Iterable[Mapping[str, Any]]) -> list[RacesBeforeAfter]:
    """Per strategy (sorted), then all strategies pooled: the paired races of ``before`` and ``after``.

    Raises ``ValueError`` when a side mixes configurations or holds a race twice, or when the two share no race."""
    by_strategy = paired_rows(before, after, _key, "race")
    out = [_line(s, pairs) for s, pairs in by_strategy.items()]
    if len(by_strategy) > 1:
        out.append(_line(ALL, [p for pairs in by_strategy.values() for p in pairs]))
    return out


def format_races_before_after(lines: Sequence[RacesBeforeAfter], before: str = "before", after: str = "after") -> str:
    """A Markdown table: each outcome as ``before → after``; races with a collision with the paired test."""
    head = (f"| strategy | paired races | success per car ({before} → {after}) | races with a collision | "
            "won / lost | p (exact McNemar) | off-track cars | stalled cars | overtakes per race | "
            "plans in force that were a fallback |")
    out = [head, "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    fmt = lambda x: "?" if x is None else str(x)  # noqa: E731
    for x in lines:
        b, a, t = x.before, x.after, x.test
        name = f"**{x.strategy}**" if x.strategy == ALL else x.strategy
        out.append(f"| {name} | {t.n} | {b.success} → {a.success} of {a.cars} | {b.collision_races} → "
                   f"{a.collision_races} | {t.a_only} / {t.b_only} | {t.p_value:.3g} | {b.off_track} → {a.off_track} "
                   f"| {b.stalled} → {a.stalled} | {b.overtakes / t.n:.2f} → {a.overtakes / t.n:.2f} | "
                   f"{fmt(b.fallbacks)} → {fmt(a.fallbacks)} |")
    return "\n".join(out) + "\n"
