"""sofar_agents.evaluation.results: episode/trace CSV files, older formats, torn lines and resume keys."""

from __future__ import annotations

import csv

import numpy as np
import pytest

from sofar_agents import evaluation as ev
from sofar_agents.evaluation.results import _AppendingCSV, _row_key

OLD_COLUMNS = [c for c in ev.EPISODE_COLUMNS if c not in ("stack", "n_opponents", "config_hash")]


def _task(**kw) -> ev.EpisodeTask:
    args = dict(track="Monza", strategy=ev.Strategy.fixed(0.5), rho=0.3, episode=1, seed=42)
    args.update(kw)
    return ev.EpisodeTask(**args)


def _result(task: ev.EpisodeTask, **kw) -> ev.EpisodeResult:
    fields = dict(track=task.track, strategy=task.strategy.name, rho=task.rho, seed=task.seed, success=True,
                  sim_time=200.0, laps=1.25, overtakes=3, collision=False, off_track=False, slack_steps=7,
                  steps=2000, mean_gamma=0.5, mpc_failures=0, miqp_failures=1, wall_time=12.5,
                  episode=task.episode, use_miqp=task.use_miqp, duration=task.duration,
                  policy_id=task.strategy.policy_id, stack=task.stack,
                  n_opponents="" if task.n_opponents is None else task.n_opponents, config_hash=task.config_hash)
    fields.update(kw)
    return ev.EpisodeResult(**fields)


def _write(path, rows, columns=ev.EPISODE_COLUMNS) -> None:
    out = _AppendingCSV(path, columns)
    try:
        for r in rows:
            out.write(r)
    finally:
        out.close()


def test_round_trip_types_and_resume_keys(tmp_path):
    path = tmp_path / "episodes.csv"
    tasks = [_task(), _task(stack="paper"), _task(n_opponents=2), _task(use_miqp=False, duration=20.0)]
    _write(path, [_result(t).to_row() for t in tasks])
    rows = ev.read_episode_csv(path)
    assert len(rows) == 4
    r = rows[0]
    assert r["success"] is True and r["use_miqp"] is True and r["collision"] is False
    assert r["seed"] == 42 and r["overtakes"] == 3 and r["rho"] == 0.3 and r["laps"] == 1.25
    assert [_row_key(r) for r in rows] == [t.key for t in tasks]  # the row of a task resumes that task
    assert rows[1]["stack"] == "paper" and rows[2]["n_opponents"] == "2" and rows[0]["n_opponents"] == ""
    # select_rows: only the given tasks, each once
    _write(path, [_result(tasks[0], sim_time=1.0).to_row()])
    picked = ev.select_rows(ev.read_episode_csv(path), tasks[:2])
    assert [p["stack"] for p in picked] == ["sofar", "paper"] and picked[0]["sim_time"] == 200.0


def test_older_format_is_read_and_migrated_on_append(tmp_path):
    path = tmp_path / "episodes.csv"
    old = _result(_task()).to_row()
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=OLD_COLUMNS, extrasaction="ignore")
        w.writeheader()
        w.writerow({k: int(v) if isinstance(v, bool) else v for k, v in old.items()})
    _write(path, [_result(_task(n_opponents=3)).to_row()])
    with open(path, newline="") as f:
        header = next(csv.reader(f))
    assert header == list(ev.EPISODE_COLUMNS)
    rows = ev.read_episode_csv(path)
    # rows of older files stand for the default of their time, "sofar-1", and the default opponent count;
    # the appended row keeps the name it was run with
    assert [(r["stack"], r["n_opponents"]) for r in rows] == [("sofar-1", ""), ("sofar", "3")]
    # the old row has no configuration hash: it resumes only a task without one, never a hashed task
    assert [_row_key(r) for r in rows] == [_task(pinned_hash="", stack="sofar-1").key, _task(n_opponents=3).key]
    assert _row_key(rows[0]) != _task().key


def test_torn_last_line_is_dropped_and_appending_starts_a_new_line(tmp_path):
    path = tmp_path / "episodes.csv"
    _write(path, [_result(_task(seed=s)).to_row() for s in (1, 2)])
    text = path.read_text()
    path.write_text(text[: text.rindex("\n", 0, len(text) - 1) + 1] + "Monza,gamma=0.50,0.3,2,1,20")  # killed mid-row
    assert [r["seed"] for r in ev.read_episode_csv(path)] == [1]
    _write(path, [_result(_task(seed=3)).to_row()])
    assert [r["seed"] for r in ev.read_episode_csv(path)] == [1, 3]


def test_foreign_csv_is_refused(tmp_path):
    path = tmp_path / "other.csv"
    path.write_text("a,b\n1,2\n")
    with pytest.raises(ValueError, match="not a SOfAR episode CSV"):
        ev.read_episode_csv(path)
    with pytest.raises(ValueError, match="expected"):
        _AppendingCSV(path, ev.EPISODE_COLUMNS)
    assert ev.read_episode_csv(tmp_path / "missing.csv") == []


def test_trace_csv_round_trip(tmp_path):
    path = tmp_path / "trace.csv"
    out = _AppendingCSV(path, ev.TRACE_COLUMNS)
    out.write_many([("Monza", "adaptive", "0.3", 1, 1, 0.1, 0.25, 12.5, 0.75),
                    ("Monza", "adaptive", "0.3", 1, 2, 0.2, 0.5, float("nan"), 0.5),
                    ("Monza", "gamma=0.50", "0.3", 1, 1, 0.1, 0.5, 30.0, 1.0)])
    out.close()
    tr = ev.read_trace_csv(path, strategy="adaptive")
    np.testing.assert_array_equal(tr["gamma"], [0.25, 0.5])
    assert tr["nearest_opponent_m"][0] == 12.5 and np.isnan(tr["nearest_opponent_m"][1])
    np.testing.assert_array_equal(tr["min_barrier"], [0.75, 0.5])
    assert ev.read_trace_csv(path)["gamma"].size == 3


def test_older_format_rows_resume_before_any_append(tmp_path):
    """An old file is read as it is: its rows count as done (no episode is re-run)."""
    path = tmp_path / "episodes.csv"
    old = _result(_task()).to_row()
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=OLD_COLUMNS, extrasaction="ignore")
        w.writeheader()
        w.writerow({k: int(v) if isinstance(v, bool) else v for k, v in old.items()})
    rows = ev.read_episode_csv(path)
    assert len(rows) == 1 and rows[0]["stack"] == "sofar-1"  # the default of its time
    assert _row_key(rows[0]) == _task(pinned_hash="", stack="sofar-1").key  # read as written, hash "" (none)


def _old_format_file(path, rows) -> None:
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=OLD_COLUMNS, extrasaction="ignore")
        w.writeheader()
        for r in rows:
            w.writerow({k: int(v) if isinstance(v, bool) else v for k, v in r.items()})


# (id, old format?, the last row, how many characters its line loses when torn)
TORN_CASES = [
    ("opponent-count-12-cut-to-1", False, dict(n_opponents=12), 1),
    ("stack-paper-cut-to-pa", False, dict(stack="paper"), 4),  # row ends "...,paper,"
    ("old-duration-60-cut-to-6", True, dict(duration=60.0, policy_id=""), 1),
    ("old-float-200-cut-to-20", True, dict(duration=200.0, policy_id=""), 1),
    ("old-policy-id-cut-short", True, dict(policy_id="pasta_lagunaseca"), 6),
]


@pytest.mark.parametrize(("name", "old", "last", "cut"), TORN_CASES, ids=[c[0] for c in TORN_CASES])
def test_a_row_torn_inside_a_field_is_not_a_complete_row(tmp_path, name, old, last, cut):
    """A last line without its newline was cut mid-write: it is ignored, then dropped on append."""
    path = tmp_path / f"{name}.csv"
    rows = [_result(_task(seed=1)).to_row(), _result(_task(seed=2)).to_row() | last]
    if old:
        _old_format_file(path, rows)
    else:
        _write(path, rows)
    text = path.read_text()
    assert text.endswith("\n")
    path.write_text(text[: len(text.rstrip("\r\n")) - cut])  # killed mid-field: no newline
    assert [r["seed"] for r in ev.read_episode_csv(path)] == [1]
    _write(path, [_result(_task(seed=3)).to_row()])
    assert [r["seed"] for r in ev.read_episode_csv(path)] == [1, 3]
    assert path.read_text().endswith("\n")


def test_the_committed_results_read_fully():
    from pathlib import Path

    root = Path(__file__).resolve().parents[2] / "results"
    assert len(ev.read_episode_csv(root / "table1_episodes.csv")) == 700


def test_a_torn_trace_line_is_ignored(tmp_path):
    path = tmp_path / "trace.csv"
    out = _AppendingCSV(path, ev.TRACE_COLUMNS)
    out.write_many([("Monza", "adaptive", "0.3", 1, 1, 0.1, 0.25, 12.5, 0.75),
                    ("Monza", "adaptive", "0.3", 1, 2, 0.2, 0.5, 30.0, 0.55)])
    out.close()
    path.write_text(path.read_text().rstrip("\r\n")[:-1])  # min_barrier 0.55 cut to 0.5
    np.testing.assert_array_equal(ev.read_trace_csv(path)["min_barrier"], [0.75])
