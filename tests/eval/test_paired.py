"""Paired comparisons of two strategies on hand-built episodes whose answers are known."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import pytest

from sofar_agents import evaluation as ev

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / "eval"))
import paired as paired_cli  # noqa: E402

from .episode_csv import write_episode_csv  # noqa: E402


def _rows(outcomes, track="X", rho=0.5, policy_id=""):
    """Rows from {strategy: [success of the episode with seed i, ...]}."""
    return [{"track": track, "rho": rho, "seed": i, "strategy": s, "success": bool(w), "use_miqp": True,
             "policy_id": policy_id if s == "adaptive" else ""}
            for s, wins in outcomes.items() for i, w in enumerate(wins)]


def test_counts_difference_and_standard_error_by_hand():
    rows = _rows({"adaptive": [1, 1, 1, 0], "gamma=0.05": [1, 0, 0, 0]})
    c = ev.paired_comparison({"S": rows}, "adaptive", "gamma=0.05")
    assert (c.n, c.a_only, c.b_only, c.unpaired) == (4, 2, 0, 0)
    assert c.success_a == pytest.approx(0.75) and c.success_b == pytest.approx(0.25)
    assert c.difference == pytest.approx(0.5)
    assert c.standard_error == pytest.approx(math.sqrt(2 - 4 / 4) / 4)
    assert c.p_value == pytest.approx(0.5)  # 2 of 2 discordant for A: 2 * (1/2)^2


def test_exact_mcnemar_p_value():
    # 9 episodes only A wins, 1 only B wins, 5 both: p = 2 * P(X <= 1), X ~ Bin(10, 1/2) = 2 * 11 / 1024
    a = [1] * 9 + [0] + [1] * 5
    b = [0] * 9 + [1] + [1] * 5
    c = ev.paired_comparison({"S": _rows({"adaptive": a, "gamma=0.5": b})}, "adaptive", "gamma=0.5")
    assert c.p_value == pytest.approx(22 / 1024)
    # symmetric in A and B; no discordant episode gives p = 1
    r = ev.paired_comparison({"S": _rows({"adaptive": a, "gamma=0.5": b})}, "gamma=0.5", "adaptive")
    assert r.p_value == pytest.approx(c.p_value) and r.difference == pytest.approx(-c.difference)
    same = ev.paired_comparison({"S": _rows({"adaptive": a, "gamma=0.5": a})}, "adaptive", "gamma=0.5")
    assert same.p_value == 1.0 and same.difference == 0.0 and same.standard_error == 0.0


def test_seed_sets_are_pooled_with_their_episodes_apart():
    s1 = _rows({"adaptive": [1, 0], "gamma=0.05": [0, 0]})
    s2 = _rows({"adaptive": [1, 1], "gamma=0.05": [1, 0]})  # the same seeds, another set
    c = ev.paired_comparison({"one": s1, "two": s2}, "adaptive", "gamma=0.05")
    assert (c.n, c.a_only, c.b_only) == (4, 2, 0)


def test_unpaired_episodes_are_left_out_and_counted():
    rows = _rows({"adaptive": [1, 1, 0], "gamma=0.05": [0, 1]})
    c = ev.paired_comparison({"S": rows}, "adaptive", "gamma=0.05")
    assert (c.n, c.a_only, c.b_only, c.unpaired) == (2, 1, 0, 1)


def test_compare_to_every_other_strategy_in_order():
    rows = _rows({"adaptive": [1, 1], "gamma=0.50": [0, 1], "gamma=0.05": [1, 0]})
    out = ev.compare_to({"S": rows}, "adaptive")
    assert [c.b for c in out] == ["gamma=0.05", "gamma=0.50"]
    text = ev.format_paired(out)
    assert "| adaptive | gamma=0.05 | 2 | 100.0 | 50.0 | +50.0 |" in text


@pytest.mark.parametrize("sets, a, b, message", [
    ({"S": _rows({"adaptive": [1]})}, "adaptive", "adaptive", "two different strategies"),
    ({"S": _rows({"adaptive": [1]})}, "adaptive", "gamma=0.3", "no episodes of strategy 'gamma=0.3'"),
    ({"S": _rows({"adaptive": [1]}, track="X") + _rows({"gamma=0.3": [1]}, track="Y")},
     "adaptive", "gamma=0.3", "share no episode"),
    ({"S": _rows({"adaptive": [1], "gamma=0.3": [1]}) * 2}, "adaptive", "gamma=0.3", "twice"),
    ({"S": _rows({"adaptive": [1], "gamma=0.3": [1]}, policy_id="p1")
     + _rows({"adaptive": [0]}, policy_id="p2")}, "adaptive", "gamma=0.3", "mixes 2 policies"),
])
def test_bad_input_is_named(sets, a, b, message):
    with pytest.raises(ValueError, match=message):
        ev.paired_comparison(sets, a, b)


def test_cli_reads_csvs_and_writes_markdown(tmp_path, capsys):
    write_episode_csv(tmp_path / "a" / "table1_episodes.csv", _rows({"adaptive": [1, 1, 0], "gamma=0.05": [1, 0, 0]}))
    write_episode_csv(tmp_path / "b" / "table1_episodes.csv", _rows({"adaptive": [1], "gamma=0.05": [0]}))
    out = tmp_path / "paired.md"
    code = paired_cli.main([str(tmp_path / "a" / "table1_episodes.csv"), str(tmp_path / "b" / "table1_episodes.csv"),
                            "--b", "gamma=0.05", "--out", str(out)])
    assert code == 0
    text = out.read_text()
    assert text == capsys.readouterr().out
    assert "| adaptive | gamma=0.05 | 4 | 75.0 | 25.0 | +50.0 |" in text


@pytest.mark.parametrize("make_args, message", [
    (lambda d: [str(d / "missing.csv")], "no such CSV"),
    (lambda d: [str(d / "a" / "table1_episodes.csv")] * 2, "given twice"),
    (lambda d: [str(d / "a" / "table1_episodes.csv"), "--a", "sb3"], "no episodes of strategy 'sb3'"),
])
def test_cli_bad_input(tmp_path, capsys, make_args, message):
    write_episode_csv(tmp_path / "a" / "table1_episodes.csv", _rows({"adaptive": [1], "gamma=0.05": [0]}))
    assert paired_cli.main(make_args(tmp_path)) == 2
    assert message in capsys.readouterr().err


def test_one_strategy_of_two_stacks_is_compared_by_stack_label():
    rows = [{**r, "stack": "sofar"} for r in _rows({"gamma=0.05": [1, 0, 0, 1]})]
    rows += [{**r, "stack": "sofar-recover"} for r in _rows({"gamma=0.05": [1, 1, 1, 1]})]
    with pytest.raises(ValueError, match="twice"):  # unlabelled, the two presets' episodes collide
        ev.paired_comparison({"S": rows}, "gamma=0.05", "adaptive")
    labelled = ev.label_by_stack({"S": rows})
    assert rows[0]["strategy"] == "gamma=0.05"  # the input is not changed
    c = ev.paired_comparison(labelled, "sofar-recover:gamma=0.05", "sofar:gamma=0.05")
    assert (c.n, c.a_only, c.b_only) == (4, 2, 0)
    # an empty stack column is the default of the time such files were written, version 1
    plain = ev.label_by_stack({"S": [{**rows[0], "stack": ""}]})
    assert plain["S"][0]["strategy"] == "sofar-1:gamma=0.05"


def test_cli_by_stack_pools_one_csv_per_preset(tmp_path, capsys):
    a, b = tmp_path / "sofar" / "table1_episodes.csv", tmp_path / "ends" / "table1_episodes.csv"
    write_episode_csv(a, [{**r, "stack": "sofar"} for r in _rows({"gamma=0.05": [1, 0, 0]})])
    write_episode_csv(b, [{**r, "stack": "sofar-ends"} for r in _rows({"gamma=0.05": [1, 1, 0]})])
    assert paired_cli.main([str(a), str(b), "--by-stack", "--a", "sofar-ends:gamma=0.05", "--b", "sofar:gamma=0.05"]) == 0
    out = capsys.readouterr().out
    assert "sofar-ends:gamma=0.05" in out and "| 3 |" in out
