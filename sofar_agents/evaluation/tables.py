"""Episode rows -> totals per group -> the Markdown of Tables I and II (pure; no files).

Per (track, strategy) the tables report the success rate [%], the cumulative
simulated time [s], the laps and overtakes summed over the episodes, plus
collisions, track-limit violations, stalled episodes (the stall rule ended them; "–"
when a row of the group predates the rule, see :mod:`~sofar_agents.evaluation.results`), barrier-slack activity (% of control steps
in which the MPC used DCBF slack), the step-weighted mean gamma and the
controller failure counts. The best value of a ranked column is **bold**, the
second best <u>underlined</u>, compared as displayed.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from sofar_agents.evaluation.protocol import TRACK_ABBREVIATIONS, TRACKS, Strategy
from sofar_agents.evaluation.results import _parse_row

PAPER_TABLE1_SUCCESS = {
    "Indianapolis": {"adaptive": 72.0, 0.05: 28.0, 0.15: 44.0, 0.30: 56.0, 0.50: 44.0, 0.70: 68.0, 0.95: 16.0},
    "Kentucky": {"adaptive": 48.0, 0.05: 12.0, 0.15: 40.0, 0.30: 44.0, 0.50: 56.0, 0.70: 24.0, 0.95: 16.0},
    "LagunaSeca": {"adaptive": 76.0, 0.05: 0.0, 0.15: 68.0, 0.30: 64.0, 0.50: 48.0, 0.70: 56.0, 0.95: 12.0},
    "Monza": {"adaptive": 72.0, 0.05: 0.0, 0.15: 60.0, 0.30: 68.0, 0.50: 84.0, 0.70: 80.0, 0.95: 0.0},
}
"""Success rates [%] of the paper's Table I (for side-by-side reporting)."""


@dataclass(frozen=True)
class Summary:
    """Totals over a group of episodes (one table cell row)."""

    episodes: int
    successes: int
    success_rate: float
    """[%]"""
    sim_time: float
    """Cumulative simulated time [s]."""
    laps: float
    overtakes: int
    collisions: int
    off_tracks: int
    stalled: float
    """Episodes the stall rule ended; NaN when any row of the group does not record it (older files)."""
    slack_pct: float
    """Percentage of control steps with DCBF slack [%]."""
    mean_gamma: float
    """Step-weighted mean gamma."""
    mpc_failures: int
    miqp_failures: int
    steps: int
    wall_time: float


def summarize(rows: Iterable[Mapping[str, Any]]) -> Summary:
    """Totals of a list of episode rows (typed dicts or raw CSV strings)."""
    rows = [_parse_row(r) for r in rows]
    n = len(rows)
    steps = sum(r["steps"] for r in rows)
    return Summary(
        episodes=n,
        successes=sum(bool(r["success"]) for r in rows),
        success_rate=100.0 * sum(bool(r["success"]) for r in rows) / n if n else math.nan,
        sim_time=float(sum(r["sim_time"] for r in rows)),
        laps=float(sum(r["laps"] for r in rows)),
        overtakes=int(sum(r["overtakes"] for r in rows)),
        collisions=int(sum(bool(r["collision"]) for r in rows)),
        off_tracks=int(sum(bool(r["off_track"]) for r in rows)),
        stalled=_stalled_count(rows),
        slack_pct=100.0 * sum(r["slack_steps"] for r in rows) / steps if steps else math.nan,
        mean_gamma=sum(r["mean_gamma"] * r["steps"] for r in rows) / steps if steps else math.nan,
        mpc_failures=int(sum(r["mpc_failures"] for r in rows)),
        miqp_failures=int(sum(r["miqp_failures"] for r in rows)),
        steps=int(steps),
        wall_time=float(sum(r["wall_time"] for r in rows)),
    )


def _stalled_count(rows: Sequence[Mapping[str, Any]]) -> float:
    """Number of stalled episodes; NaN if any row's ``stalled`` is unknown (None or missing)."""
    flags = [r.get("stalled") for r in rows]
    if any(f is None for f in flags):
        return math.nan
    return float(sum(bool(f) for f in flags))


def aggregate(rows: Iterable[Mapping[str, Any]], by: Sequence[str] = ("track", "strategy")) -> dict[tuple, Summary]:
    """:func:`summarize` per group of the columns ``by``, groups in order of first appearance."""
    groups: dict[tuple, list] = {}
    for r in rows:
        r = _parse_row(r)
        groups.setdefault(tuple(r[c] for c in by), []).append(r)
    return {k: summarize(v) for k, v in groups.items()}


def rank_marks(values: Sequence[float], higher_is_better: bool = True, decimals: int | None = None) -> list[str]:
    """``"best"``, ``"second"`` or ``""`` for each value.

    Standard competition ranking on the values as displayed (rounded to ``decimals``):
    every value equal to the best is ``"best"``; when the best is unique, every value
    equal to the next distinct one is ``"second"`` (a tie for the best leaves no second
    place, as in 1-1-3 ranking). NaN is never marked.
    """
    vals = [float(v) for v in values]
    shown = [round(v, decimals) if decimals is not None and math.isfinite(v) else v for v in vals]
    distinct = sorted({v for v in shown if math.isfinite(v)}, reverse=higher_is_better)
    best = distinct[0] if distinct else None
    second = distinct[1] if len(distinct) > 1 and shown.count(best) == 1 else None
    return ["best" if v == best else "second" if v == second else "" for v in shown]


@dataclass(frozen=True)
class _Column:
    header: str
    attr: str
    decimals: int
    rank: bool = False


_TABLE1_COLUMNS = (
    _Column("Success [%] ↑", "success_rate", 1, True),
    _Column("Sim time [s] ↑", "sim_time", 1, True),
    _Column("Laps ↑", "laps", 2, True),
    _Column("Overtakes ↑", "overtakes", 0, True),
    _Column("Collisions", "collisions", 0),
    _Column("Off-track", "off_tracks", 0),
    _Column("Stalled", "stalled", 0),
    _Column("Slack [% steps]", "slack_pct", 1),
    _Column("Mean γ", "mean_gamma", 2),
    _Column("MPC fail.", "mpc_failures", 0),
    _Column("Episodes", "episodes", 0),
)
_TABLE2_COLUMNS = (
    _Column("Succ. [%] ↑", "success_rate", 1, True),
    _Column("Time [s] ↑", "sim_time", 1, True),
    _Column("Laps ↑", "laps", 2, True),
    _Column("Overt. ↑", "overtakes", 0, True),
    _Column("Collisions", "collisions", 0),
    _Column("Off-track", "off_tracks", 0),
    _Column("Stalled", "stalled", 0),
    _Column("Slack [% steps]", "slack_pct", 1),
    _Column("Episodes", "episodes", 0),
)


def _cell(value: float, decimals: int, mark: str) -> str:
    text = "–" if not math.isfinite(float(value)) else f"{float(value):.{decimals}f}"
    return f"**{text}**" if mark == "best" else f"<u>{text}</u>" if mark == "second" else text


def _markdown_blocks(first_header: str, blocks: Sequence[tuple[str, Sequence[tuple[str, Summary]]]],
                     columns: Sequence[_Column], rank_within_block: bool = True) -> str:
    head = [first_header, "Strategy", *[c.header for c in columns]]
    lines = ["| " + " | ".join(head) + " |", "|" + "|".join(["---", "---"] + ["---:"] * len(columns)) + "|"]
    all_rows = [(b, lab, s) for b, rows in blocks for lab, s in rows]

    def marks_for(items):
        return {c.attr: rank_marks([getattr(s, c.attr) for _, _, s in items], True, c.decimals) if c.rank
                else [""] * len(items) for c in columns}

    if rank_within_block:
        marks = {}
        for b, rows in blocks:
            items = [(b, lab, s) for lab, s in rows]
            m = marks_for(items)
            for i, it in enumerate(items):
                marks[id(it[2]), b, it[1]] = {a: m[a][i] for a in m}
    else:
        m = marks_for(all_rows)
        marks = {(id(s), b, lab): {a: m[a][i] for a in m} for i, (b, lab, s) in enumerate(all_rows)}
    for b, rows in blocks:
        for j, (lab, s) in enumerate(rows):
            mk = marks[id(s), b, lab]
            cells = [b if j == 0 else "", lab] + [_cell(getattr(s, c.attr), c.decimals, mk[c.attr]) for c in columns]
            lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _one_config(rows: Sequence[Mapping[str, Any]]) -> None:
    from sofar_agents.evaluation.configs import check_one_config

    check_one_config(rows, lambda r: str(r["strategy"]), "table")


def format_table1(rows: Iterable[Mapping[str, Any]], strategies: Sequence[Strategy] | None = None,
                  tracks: Sequence[str] | None = None, aggregate_row: bool = True) -> str:
    """Table I as Markdown: per track, one row per strategy; best **bold**, second <u>underlined</u>.

    Ranking is within each track (and within the aggregate block over all tracks) for success
    rate, simulated time, laps and overtakes (higher is better). Rows of one strategy with two
    configuration hashes (or with one and without) raise ``ValueError`` naming both.
    """
    rows = [_parse_row(r) for r in rows]
    _one_config(rows)
    if tracks is None:
        tracks = [t for t in TRACKS if any(r["track"] == t for r in rows)]
        tracks += sorted({r["track"] for r in rows} - set(tracks))
    if strategies is None:
        names = list(dict.fromkeys(r["strategy"] for r in rows))
        labels = {n: n for n in names}
    else:
        names = [s.name for s in strategies]
        labels = {s.name: s.label for s in strategies}
    per = aggregate(rows, ("track", "strategy"))
    blocks = []
    for t in tracks:
        items = [(labels[n], per[(t, n)]) for n in names if (t, n) in per]
        if items:
            abbr = TRACK_ABBREVIATIONS.get(t, t)
            blocks.append((t if abbr == t else f"{t} ({abbr})", items))
    if aggregate_row and len(blocks) > 1:
        tot = aggregate([r for r in rows if r["track"] in tracks], ("strategy",))
        blocks.append(("All circuits", [(labels[n], tot[(n,)]) for n in names if (n,) in tot]))
    return _markdown_blocks("Track", blocks, _TABLE1_COLUMNS)


def format_table2(rows: Iterable[Mapping[str, Any]], strategies: Sequence[Strategy] | None = None) -> str:
    """Table II as Markdown: with and without the MIQP layer; ranking over all four rows as in the paper.
    Rows of one strategy from two configurations raise ``ValueError`` as in :func:`format_table1`."""
    rows = [_parse_row(r) for r in rows]
    _one_config(rows)
    names = [s.name for s in strategies] if strategies else list(dict.fromkeys(r["strategy"] for r in rows))
    labels = {s.name: s.label for s in strategies} if strategies else {n: n for n in names}
    per = aggregate(rows, ("use_miqp", "strategy"))
    blocks = []
    for use, title in ((False, "w/o MIQP"), (True, "w/ MIQP")):
        items = [(labels[n], per[(use, n)]) for n in names if (use, n) in per]
        if items:
            blocks.append((title, items))
    return _markdown_blocks("Setting", blocks, _TABLE2_COLUMNS, rank_within_block=False)


def paper_comparison(rows: Iterable[Mapping[str, Any]], strategies: Sequence[Strategy]) -> str:
    """Markdown: our success rate next to the paper's (Table I) for the strategies the paper has."""
    per = aggregate(rows, ("track", "strategy"))
    lines = ["| Track | Strategy | Success [%] (this run) | Success [%] (paper) |", "|---|---|---:|---:|"]
    for t in TRACKS:
        for s in strategies:
            key = "adaptive" if s.kind == "policy" else s.gamma if s.kind == "fixed" else None  # the exact gamma
            paper = PAPER_TABLE1_SUCCESS.get(t, {}).get(key)
            if (t, s.name) in per and paper is not None:
                lines.append(f"| {t} | {s.label} | {per[(t, s.name)].success_rate:.1f} | {paper:.1f} |")
    return "\n".join(lines) if len(lines) > 2 else ""
