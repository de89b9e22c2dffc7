"""The before and after of a controller change on the same episodes: counts, the paired test, refusals."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

from sofar_agents.evaluation.before_after import FIXED, before_after, format_before_after

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "eval"))
import paired as script  # noqa: E402

from .episode_csv import write_episode_csv  # noqa: E402


def _rows(stack, h, outcomes, **extra):
    """One row per (strategy, seed): outcomes maps strategy -> list of (success, collision, stalled)."""
    return [{"track": "Monza", "rho": 0.3, "seed": seed, "strategy": s, "success": ok, "collision": col,
             "stalled": st, "off_track": 0, "overtakes": 4, "sim_time": 180.0, "use_miqp": 1, "stack": stack,
             "config_hash": h, **extra}
            for s, eps in outcomes.items() for seed, (ok, col, st) in enumerate(eps)]


def test_counts_and_the_paired_test_by_hand():
    before = _rows("sofar-1", "aaa", {"gamma=0.05": [(1, 0, 0), (0, 0, 1), (0, 1, 0), (1, 0, 0)],
                                      "gamma=0.5": [(1, 0, 0), (1, 0, 0)]})
    after = _rows("sofar", "bbb", {"gamma=0.05": [(1, 0, 0), (1, 0, 0), (1, 0, 0), (0, 1, 0)],
                                   "gamma=0.5": [(1, 0, 0), (1, 0, 0), (1, 0, 0)]})  # a third episode: unpaired
    lines = {x.strategy: x for x in before_after(before, after)}
    g = lines["gamma=0.05"]
    assert (g.test.n, g.before.success, g.after.success, g.test.a_only, g.test.b_only) == (4, 2, 3, 2, 1)
    assert g.test.p_value == pytest.approx(1.0)  # 2 against 1 of 3 discordant: exact two-sided p = 1
    assert (g.before.collisions, g.after.collisions, g.before.stalls, g.after.stalls) == (1, 1, 1, 0)
    assert g.before.overtakes_per_hour == pytest.approx(16 / (720 / 3600))
    assert lines["gamma=0.5"].test.n == 2  # the unpaired episode is left out
    assert lines[FIXED].test.n == 6 and lines[FIXED].after.success == 5
    assert "2 → 3" in format_before_after(list(lines.values()))


def test_a_side_of_two_configurations_or_no_shared_episode_is_refused():
    mixed = _rows("sofar", "aaa", {"gamma=0.05": [(1, 0, 0)]}) + [
        {**_rows("sofar", "ccc", {"gamma=0.05": [(1, 0, 0)]})[0], "seed": 7}]
    with pytest.raises(ValueError, match="two configurations"):
        before_after(_rows("sofar-1", "aaa", {"gamma=0.05": [(1, 0, 0)]}), mixed)
    other = [{**r, "seed": 99} for r in _rows("sofar", "bbb", {"gamma=0.05": [(1, 0, 0)]})]
    with pytest.raises(ValueError, match="share no episode"):
        before_after(_rows("sofar-1", "aaa", {"gamma=0.05": [(1, 0, 0)]}), other)


def test_the_script_compares_two_csvs(tmp_path, capsys):
    a, b = tmp_path / "before" / "table1_episodes.csv", tmp_path / "after" / "table1_episodes.csv"
    write_episode_csv(a, _rows("sofar-1", "aaa", {"gamma=0.05": [(0, 0, 1), (1, 0, 0)]}))
    write_episode_csv(b, _rows("sofar", "bbb", {"gamma=0.05": [(1, 0, 0), (1, 0, 0)]}))
    assert script.main(["--before-after", str(a), str(b), "--out", str(tmp_path / "ba.md")]) == 0
    assert "| gamma=0.05 | 2 | 1 → 2 | 1 / 0 |" in capsys.readouterr().out
    assert script.main(["--before-after", str(a)]) == 2
