"""The headroom oracles on hand-built tables whose answers are known."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

from sofar_agents import evaluation as ev

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / "eval"))
import headroom as headroom_cli  # noqa: E402

from .episode_csv import write_episode_csv  # noqa: E402


def _rows(outcomes, seed0=0, extra=None):
    """Rows from {(track, rho): {gamma: [success, ...]}}; episode i of a cell has seed seed0 + i."""
    rows = []
    for (track, rho), cells in outcomes.items():
        for gamma, wins in cells.items():
            for i, w in enumerate(wins):
                rows.append({"track": track, "rho": rho, "seed": seed0 + i, "strategy": f"gamma={gamma:.2f}",
                             "success": bool(w), "use_miqp": True})
    return rows + list(extra or [])


# Set A: gamma 0.05 wins condition (X, 0.1) and 0.5 wins (X, 0.8); 0.05 is better overall.
SET_A = {("X", 0.1): {0.05: [1, 1, 1, 1], 0.5: [0, 0, 1, 0]},
         ("X", 0.8): {0.05: [1, 1, 0, 0], 0.5: [1, 1, 1, 0]}}
# Set B: the same shape with the condition preferences swapped.
SET_B = {("X", 0.1): {0.05: [0, 1, 0, 0], 0.5: [1, 1, 0, 1]},
         ("X", 0.8): {0.05: [1, 1, 1, 1], 0.5: [1, 0, 0, 1]}}


def test_single_set_oracles_by_hand():
    (row,) = ev.headroom({"A": _rows(SET_A)})
    assert row.episodes == 8
    assert row.best_fixed_gamma == 0.05 and row.best_fixed == pytest.approx(6 / 8)
    assert row.condition_oracle_in_sample == pytest.approx((4 / 4 + 3 / 4) / 2)
    assert row.condition_oracle_cross is None and row.circuit_oracle_cross is None
    # episodes some gamma wins: (X,0.1) all 4; (X,0.8) seeds 0,1,2 -> 7 of 8; every gamma: 1 + 2 -> 3 of 8
    assert row.episode_oracle == pytest.approx(7 / 8)
    assert row.all_gammas_win == pytest.approx(3 / 8)
    assert row.standard_error == pytest.approx((0.75 * 0.25 / 8) ** 0.5)


def test_cross_set_oracle_uses_the_other_sets_choice():
    a, b = ev.headroom({"A": _rows(SET_A), "B": _rows(SET_B)})
    # B picks 0.5 for (X, 0.1) and 0.05 for (X, 0.8): scored on A, 1/4 and 2/4
    assert a.condition_oracle_cross == pytest.approx((1 / 4 + 2 / 4) / 2)
    # A picks 0.05 for (X, 0.1) and 0.5 for (X, 0.8): scored on B, 1/4 and 2/4
    assert b.condition_oracle_cross == pytest.approx((1 / 4 + 2 / 4) / 2)
    # one circuit: A's best overall is 0.05 (6/8 vs 4/8); B's: 0.05 (5/8) vs 0.5 (5/8) tie -> overall of A (0.05)
    assert b.circuit_oracle_cross == pytest.approx(5 / 8)
    assert a.circuit_oracle_cross == pytest.approx(6 / 8)


def test_only_fixed_gamma_rows_with_the_miqp_count():
    extra = [{"track": "X", "rho": 0.1, "seed": 0, "strategy": "adaptive", "success": True, "use_miqp": True},
             {"track": "X", "rho": 0.1, "seed": 0, "strategy": "gamma=0.95", "success": True, "use_miqp": False}]
    (row,) = ev.headroom({"A": _rows(SET_A, extra=extra)})
    assert row.best_fixed == pytest.approx(6 / 8) and row.episodes == 8


def test_outcome_flips_count_paired_episodes_that_differ():
    flips = ev.outcome_flips(_rows(SET_A))
    # (X,0.1): 0.05 [1,1,1,1] vs 0.5 [0,0,1,0] -> 3 differ; (X,0.8): [1,1,0,0] vs [1,1,1,0] -> 1 differs
    assert flips == {(0.05, 0.5): (pytest.approx(4 / 8), 8)}
    text = ev.format_flips(flips)
    assert "| 0.05 |  | 50 |" in text and "| 0.5 | 50 |  |" in text


@pytest.mark.parametrize("sets, match", [
    ({"A": []}, "no fixed-gamma rows"),
    ({"A": _rows(SET_A)[:-1]}, "lack some gamma"),
    ({"A": _rows(SET_A), "B": _rows({("X", 0.1): {0.3: [1]}})}, "share no fixed gamma"),
])
def test_bad_tables_are_refused(sets, match):
    with pytest.raises(ValueError, match=match):
        ev.headroom(sets)


def test_cli_reads_csvs_and_writes_markdown(tmp_path, capsys):
    write_episode_csv(tmp_path / "a" / "table1_episodes.csv", _rows(SET_A))
    write_episode_csv(tmp_path / "b" / "table1_episodes.csv", _rows(SET_B))
    out = tmp_path / "headroom.md"
    code = headroom_cli.main([str(tmp_path / "a" / "table1_episodes.csv"),
                              str(tmp_path / "b" / "table1_episodes.csv"), "--out", str(out)])
    assert code == 0
    text = out.read_text()
    assert text == capsys.readouterr().out
    assert "| 75.0 |" in text and str(tmp_path / "b") in text
    assert headroom_cli.main([str(tmp_path / "a" / "table1_episodes.csv"), "--flips"]) == 0
    assert "Outcome flips" in capsys.readouterr().out


@pytest.mark.parametrize("make_args, message", [
    (lambda d: [str(d / "missing.csv")], "no such CSV"),
    (lambda d: [str(d / "a" / "table1_episodes.csv")] * 2, "given twice"),
])
def test_cli_bad_input(tmp_path, capsys, make_args, message):
    write_episode_csv(tmp_path / "a" / "table1_episodes.csv", _rows(SET_A))
    assert headroom_cli.main(make_args(tmp_path)) == 2
    assert message in capsys.readouterr().err
