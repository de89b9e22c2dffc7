"""The ``stalled`` column: per-episode rows, older files (unknown), and the tables' stalled count."""

from __future__ import annotations

import csv
from pathlib import Path

import pytest

from sofar_agents import evaluation as ev
from sofar_agents.evaluation.results import _AppendingCSV
from sofar_agents.evaluation.tables import format_table1, format_table2, summarize

ROOT = Path(__file__).resolve().parents[2]
PRE_STALL_COLUMNS = [c for c in ev.EPISODE_COLUMNS if c != "stalled"]


def _row(seed: int, **kw) -> dict:
    task = ev.EpisodeTask(track="Monza", strategy=ev.Strategy.fixed(0.5), rho=0.0, episode=seed, seed=seed)
    fields = dict(track=task.track, strategy=task.strategy.name, rho=task.rho, seed=task.seed, success=True,
                  sim_time=200.0, laps=1.0, overtakes=3, collision=False, off_track=False, slack_steps=0,
                  steps=2000, mean_gamma=0.5, mpc_failures=0, miqp_failures=0, wall_time=1.0, episode=seed)
    fields.update(kw)
    return ev.EpisodeResult(**fields).to_row()


def _write(path, rows, columns) -> None:
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=columns, extrasaction="ignore")
        w.writeheader()
        for r in rows:
            w.writerow({k: int(v) if isinstance(v, bool) else v for k, v in r.items()})


def test_stalled_round_trips(tmp_path):
    path = tmp_path / "episodes.csv"
    out = _AppendingCSV(path, ev.EPISODE_COLUMNS)
    out.write(_row(1, stalled=True, success=False, sim_time=38.0))
    out.write(_row(2))
    out.close()
    rows = ev.read_episode_csv(path)
    assert [r["stalled"] for r in rows] == [True, False]
    assert summarize(rows).stalled == 1


def test_rows_of_files_before_the_rule_are_unknown_and_migrate_as_unknown(tmp_path):
    path = tmp_path / "episodes.csv"
    _write(path, [_row(1)], PRE_STALL_COLUMNS)
    assert ev.read_episode_csv(path)[0]["stalled"] is None
    out = _AppendingCSV(path, ev.EPISODE_COLUMNS)  # migrates the file
    out.write(_row(2, stalled=True, success=False))
    out.close()
    with open(path, newline="") as f:
        assert next(csv.reader(f)) == list(ev.EPISODE_COLUMNS)
    rows = ev.read_episode_csv(path)
    assert [r["stalled"] for r in rows] == [None, True]
    assert summarize(rows[1:]).stalled == 1
    assert summarize(rows).stalled != summarize(rows).stalled  # NaN: one row does not record it


def test_tables_show_the_stalled_count():
    rows = [_row(1, stalled=True, success=False), _row(2), _row(3, stalled=True, success=False)]
    for table in (format_table1(rows), format_table2(rows)):
        header, _, line = table.splitlines()[:3]
        cells = [c.strip() for c in line.strip("|").split("|")]
        assert cells[[c.strip() for c in header.strip("|").split("|")].index("Stalled")] == "2"


@pytest.mark.parametrize("name,recorded_with_rule", [
    ("table1_episodes.csv", True), ("table2_episodes.csv", True), ("paper_stack/table1_episodes.csv", True),
    ("paper_stack/table2_episodes.csv", True), ("interactive/table1_episodes.csv", True),
    ("interactive_dense/table1_episodes.csv", True),
    ("seed13/table1_episodes.csv", True), ("seed14/table1_episodes.csv", True), ("first format", False),
])
def test_committed_results_still_read_and_render(name, recorded_with_rule, tmp_path):
    """The committed tables re-run with the stall rule carry it per row; rows of the first format (recorded before
    the rule, as the held-out seed sets once were) read as unknown ("–"), not as 0."""
    path = ROOT / "results" / name
    if not recorded_with_rule:
        from .episode_csv import FIRST_FORMAT

        path = tmp_path / "table1_episodes.csv"
        path.write_text(FIRST_FORMAT)
    rows = ev.read_episode_csv(path)
    assert rows
    if recorded_with_rule:
        assert all(isinstance(r["stalled"], bool) for r in rows)
        # a stalled episode is never a success
        assert not any(r["stalled"] and r["success"] for r in rows)
    else:
        assert all(r["stalled"] is None for r in rows)
    table = (format_table1 if "table1" in name else format_table2)(rows)
    assert "| Stalled |" in table
    assert ("| – |" in table) != recorded_with_rule
