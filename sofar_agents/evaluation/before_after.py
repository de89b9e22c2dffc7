"""Two controllers on the same seeded episodes, every outcome: the before and after of a change of controller.

:func:`before_after` pairs the rows of two Table I runs (``table1_episodes.csv``) of the same episodes, made
with two controllers (or two versions of one), episode by episode: same circuit, pace ratio, seed and MIQP
setting, per strategy. For each strategy, and for all fixed gammas together, it counts successes (with the
exact McNemar test of :class:`~sofar_agents.evaluation.paired.PairedComparison`), collisions, off-tracks,
stalls and overtakes per hour of simulated time over the paired episodes only. Rows of one side must come from
one configuration (one ``config_hash``; :func:`~sofar_agents.evaluation.configs.check_one_config`).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from .paired import PairedComparison

__all__ = ["Outcomes", "BeforeAfter", "paired_rows", "before_after", "format_before_after"]

FIXED = "all fixed gammas"
"""The label of the line that pools every ``gamma=...`` strategy."""


@dataclass(frozen=True)
class Outcomes:
    """Counts of one side over the paired episodes."""

    success: int
    collisions: int
    off_tracks: int
    stalls: int
    overtakes: int
    hours: float

    @property
    def overtakes_per_hour(self) -> float:
        return self.overtakes / self.hours if self.hours > 0 else float("nan")


@dataclass(frozen=True)
class BeforeAfter:
    """One strategy before and after: the paired test of success and both sides' outcomes."""

    strategy: str
    test: PairedComparison
    before: Outcomes
    after: Outcomes


def _key(r: Mapping[str, Any]) -> tuple:
    miqp = str(r.get("use_miqp", True)).strip().lower() not in ("false", "0", "")
    return (str(r["track"]), round(float(r["rho"]), 6), int(r["seed"]), miqp, str(r["strategy"]))


def _flag(value: Any) -> int:
    return int(float(value)) if value not in ("", None) else 0


def _index(rows: Iterable[Mapping[str, Any]], side: str, key: Callable[[Mapping[str, Any]], tuple],
           what: str) -> dict[tuple, Mapping[str, Any]]:
    from sofar_agents.evaluation.configs import check_one_config

    rows = list(rows)
    check_one_config(rows, lambda r: str(r["strategy"]), f"the {side} rows")
    out: dict[tuple, Mapping[str, Any]] = {}
    for r in rows:
        k = key(r)
        if k in out:
            raise ValueError(f"the {side} rows hold {what} {k[:-1]} of strategy {k[-1]!r} twice")
        out[k] = r
    return out


def paired_rows(before: Iterable[Mapping[str, Any]], after: Iterable[Mapping[str, Any]],
                key: Callable[[Mapping[str, Any]], tuple] = _key, what: str = "episode") -> dict[str, list[tuple]]:
    """The ``(before, after)`` row pairs with the same ``key`` (a tuple ending with the strategy), grouped by strategy
    (sorted). ``what`` names a row in the messages. Raises ``ValueError`` when a side mixes configurations or holds a
    key twice, or when the two share none."""
    b, a = _index(before, "before", key, what), _index(after, "after", key, what)
    common = sorted(b.keys() & a.keys())
    if not common:
        raise ValueError(f"the before and after rows share no {what} (different seeds, circuits or strategies)")
    by_strategy: dict[str, list[tuple]] = {}
    for k in common:
        by_strategy.setdefault(k[-1], []).append((b[k], a[k]))
    return dict(sorted(by_strategy.items()))


def _outcomes(rows: Sequence[Mapping[str, Any]]) -> Outcomes:
    return Outcomes(success=sum(_flag(r["success"]) for r in rows),
                    collisions=sum(_flag(r["collision"]) for r in rows),
                    off_tracks=sum(_flag(r["off_track"]) for r in rows),
                    stalls=sum(_flag(r.get("stalled")) for r in rows),
                    overtakes=sum(_flag(r["overtakes"]) for r in rows),
                    hours=sum(float(r["sim_time"]) for r in rows) / 3600.0)


def _line(name: str, pairs: Sequence[tuple[Mapping[str, Any], Mapping[str, Any]]]) -> BeforeAfter:
    b_rows, a_rows = [p[0] for p in pairs], [p[1] for p in pairs]
    won = sum(1 for b, a in pairs if _flag(a["success"]) and not _flag(b["success"]))
    lost = sum(1 for b, a in pairs if _flag(b["success"]) and not _flag(a["success"]))
    n = len(pairs)
    test = PairedComparison(a="after", b="before", n=n, success_a=sum(_flag(r["success"]) for r in a_rows) / n,
                            success_b=sum(_flag(r["success"]) for r in b_rows) / n, a_only=won, b_only=lost,
                            unpaired=0)
    return BeforeAfter(name, test, _outcomes(b_rows), _outcomes(a_rows))


def before_after(before: Iterable[Mapping[str, Any]], after: Iterable[Mapping[str, Any]]) -> list[BeforeAfter]:
    """Per strategy (sorted), then all fixed gammas pooled: the paired episodes of ``before`` and ``after``.

    Raises ``ValueError`` when a side mixes configurations or holds an episode twice, or when the two share no
    episode."""
    by_strategy = paired_rows(before, after)
    out = [_line(s, pairs) for s, pairs in by_strategy.items()]
    fixed = [p for s, pairs in by_strategy.items() if s.startswith("gamma=") for p in pairs]
    if fixed:
        out.append(_line(FIXED, fixed))
    return out


def format_before_after(lines: Sequence[BeforeAfter], before: str = "before", after: str = "after") -> str:
    """A Markdown table: each outcome as ``before → after``, success with the paired test."""
    head = (f"| strategy | paired episodes | success ({before} → {after}) | won / lost | p (exact McNemar) "
            "| collisions | off-tracks | stalls | overtakes per hour |")
    lines_out = [head, "|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for x in lines:
        b, a, t = x.before, x.after, x.test
        name = f"**{x.strategy}**" if x.strategy == FIXED else x.strategy
        lines_out.append(f"| {name} | {t.n} | {b.success} → {a.success} | {t.a_only} / {t.b_only} | {t.p_value:.3g} "
                         f"| {b.collisions} → {a.collisions} | {b.off_tracks} → {a.off_tracks} | {b.stalls} → "
                         f"{a.stalls} | {b.overtakes_per_hour:.0f} → {a.overtakes_per_hour:.0f} |")
    return "\n".join(lines_out) + "\n"
