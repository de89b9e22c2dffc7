"""The before and after of a controller change on the same multi-car races: counts, the paired test, refusals."""

from __future__ import annotations

import csv
import sys
from pathlib import Path

import pytest

from sofar_agents.evaluation.multi_agent import RACE_COLUMNS
from sofar_agents.evaluation.races_before_after import ALL, format_races_before_after, races_before_after

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "eval"))
import paired as script  # noqa: E402


def _rows(stack, h, races, fallbacks=None):
    """races maps strategy -> list of (success cars, colliding cars, overtakes), one race per seed."""
    return [{"track": "Monza", "strategy": s, "policy_id": "", "seed": str(seed), "cars": "4", "duration": "200",
             "stack": stack, "config_hash": h, "scenario": "paper", "overtakes": str(ov), "collided": str(col),
             "off_track": "0", "stalled": "0", "success": str(ok), "driven": "1", "mean_gamma": "0.5",
             "speed_factors": "1 1 1 1", "wall_time": "1", "opponents": "0",
             "miqp_failures": "-1" if fallbacks is None else str(fallbacks)}
            for s, rs in races.items() for seed, (ok, col, ov) in enumerate(rs)]


def test_counts_and_the_paired_test_by_hand():
    before = _rows("sofar-13", "aaa", {"gamma=0.50": [(4, 0, 2), (2, 2, 1), (2, 2, 3), (4, 0, 2)],
                                       "self-play": [(4, 0, 1)]})
    after = _rows("sofar-14", "bbb", {"gamma=0.50": [(4, 0, 2), (4, 0, 2), (4, 0, 4), (2, 2, 2)],
                                      "self-play": [(4, 0, 1), (4, 0, 1)]}, fallbacks=0)  # a second race: unpaired
    lines = {x.strategy: x for x in races_before_after(before, after)}
    g = lines["gamma=0.50"]
    assert (g.test.n, g.before.success, g.after.success) == (4, 12, 14)
    assert (g.before.collision_races, g.after.collision_races, g.test.a_only, g.test.b_only) == (2, 1, 2, 1)
    assert g.test.p_value == pytest.approx(1.0)  # 2 against 1 of 3 discordant races: exact two-sided p = 1
    assert (g.before.overtakes, g.after.overtakes) == (8, 10)
    assert g.before.fallbacks is None and g.after.fallbacks == 0  # the before CSV predates the column
    assert lines["self-play"].test.n == 1 and lines[ALL].test.n == 5
    text = format_races_before_after(list(lines.values()))
    assert "12 → 14 of 16" in text and "? → 0" in text and "2.00 → 2.50" in text


@pytest.mark.parametrize("before,after,words", [
    (_rows("a", "aaa", {"gamma=0.50": [(4, 0, 1)]}),
     [{**r, "seed": "7"} for r in _rows("b", "bbb", {"gamma=0.50": [(4, 0, 1)]})], "share no race"),
    (_rows("a", "aaa", {"gamma=0.50": [(4, 0, 1)]}) * 2, _rows("b", "bbb", {"gamma=0.50": [(4, 0, 1)]}), "twice"),
    (_rows("a", "aaa", {"gamma=0.50": [(4, 0, 1)]}) + [{**_rows("a", "ccc", {"gamma=0.50": [(4, 0, 1), (4, 0, 1)]})[1]}],
     _rows("b", "bbb", {"gamma=0.50": [(4, 0, 1)]}), "two configurations"),
])
def test_bad_pairs_are_refused(before, after, words):
    with pytest.raises(ValueError, match=words):
        races_before_after(before, after)


def _write(path: Path, rows) -> Path:
    with open(path, "w", newline="") as f:
        writer = csv.DictWriter(f, RACE_COLUMNS)
        writer.writeheader()
        writer.writerows(rows)
    return path


def test_the_script_reads_race_csvs_old_and_new(tmp_path, capsys):
    old = _rows("sofar-13", "aaa", {"gamma=0.30": [(4, 0, 2), (2, 2, 1)]})
    old_path = tmp_path / "old.csv"
    columns = [c for c in RACE_COLUMNS if c != "miqp_failures"]  # a CSV from before the column
    with open(old_path, "w", newline="") as f:
        writer = csv.DictWriter(f, columns, extrasaction="ignore")
        writer.writeheader()
        writer.writerows(old)
    new_path = _write(tmp_path / "new.csv", _rows("sofar-14", "bbb", {"gamma=0.30": [(4, 0, 2), (4, 0, 3)]}, 0))
    assert script.main(["--before-after", "--races", str(old_path), str(new_path)]) == 0
    out = capsys.readouterr().out
    assert "| gamma=0.30 | 2 | 6 → 8 of 8 | 1 → 0 | 1 / 0 |" in out and "? → 0" in out
    assert script.main(["--races", str(old_path), str(new_path)]) == 2  # --races needs --before-after
