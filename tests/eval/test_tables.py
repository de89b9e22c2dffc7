"""sofar_agents.evaluation.tables: totals per group, best/second marks and the Markdown of Tables I/II."""

from __future__ import annotations

import pytest

from sofar_agents import evaluation as ev


def _row(track, strategy, success, sim_time, laps, overtakes, steps=100, slack=0, gamma=0.5, collision=None,
         off_track=False, rho=0.3, seed=1, mpc_failures=0):
    return {
        "track": track, "strategy": strategy, "rho": rho, "seed": seed, "success": success, "sim_time": sim_time,
        "laps": laps, "overtakes": overtakes, "collision": (not success) if collision is None else collision,
        "off_track": off_track, "slack_steps": slack, "steps": steps, "mean_gamma": gamma,
        "mpc_failures": mpc_failures, "miqp_failures": 0, "wall_time": 1.0, "episode": 0, "use_miqp": True,
        "duration": 200.0, "policy_id": "",
    }


def test_summarize_hand_computed():
    rows = [
        _row("LagunaSeca", "gamma=0.50", True, 200.0, 1.5, 3, steps=2000, slack=100, gamma=0.5),
        _row("LagunaSeca", "gamma=0.50", False, 50.0, 0.25, 1, steps=500, slack=100, gamma=0.8, mpc_failures=2),
        _row("LagunaSeca", "gamma=0.50", True, 200.0, 1.75, 0, steps=2000, slack=0, gamma=0.2),
        _row("LagunaSeca", "gamma=0.50", False, 10.0, 0.0, 0, steps=100, slack=0, gamma=0.5, collision=False,
             off_track=True),
    ]
    s = ev.summarize(rows)
    assert s.episodes == 4 and s.successes == 2
    assert s.success_rate == pytest.approx(50.0)
    assert s.sim_time == pytest.approx(460.0)
    assert s.laps == pytest.approx(3.5)
    assert s.overtakes == 4
    assert s.collisions == 1 and s.off_tracks == 1
    assert s.steps == 4600
    assert s.slack_pct == pytest.approx(100.0 * 200 / 4600)
    assert s.mean_gamma == pytest.approx((0.5 * 2000 + 0.8 * 500 + 0.2 * 2000 + 0.5 * 100) / 4600)
    assert s.mpc_failures == 2


def test_aggregate_groups_and_parses_csv_strings():
    rows = [_row("Monza", "a", True, 200.0, 1.0, 2), _row("Monza", "b", False, 20.0, 0.1, 0),
            _row("Kentucky", "a", False, 30.0, 0.5, 1)]
    as_strings = [{k: str(int(v) if isinstance(v, bool) else v) for k, v in r.items()} for r in rows]
    per = ev.aggregate(as_strings)
    assert list(per) == [("Monza", "a"), ("Monza", "b"), ("Kentucky", "a")]
    assert per[("Monza", "a")].success_rate == 100.0
    assert per[("Monza", "b")].success_rate == 0.0
    tot = ev.aggregate(as_strings, ("strategy",))
    assert tot[("a",)].episodes == 2 and tot[("a",)].success_rate == 50.0 and tot[("a",)].overtakes == 3


def test_rank_marks_best_second_and_ties():
    assert ev.rank_marks([1, 3, 2]) == ["", "best", "second"]
    assert ev.rank_marks([3, 3, 2, 1]) == ["best", "best", "", ""]  # tie for best: no second place
    assert ev.rank_marks([3, 2, 2, 1]) == ["best", "second", "second", ""]  # tie for second
    assert ev.rank_marks([5, 5, 5]) == ["best", "best", "best"]  # no second place
    assert ev.rank_marks([1, 3, 2], higher_is_better=False) == ["best", "", "second"]
    assert ev.rank_marks([float("nan"), 1.0, 0.5]) == ["", "best", "second"]
    # compared as displayed: 72.04 and 72.01 both read 72.0
    assert ev.rank_marks([72.04, 72.01, 68.0], decimals=1) == ["best", "best", ""]
    assert ev.rank_marks([72.04, 72.01, 68.0], decimals=2) == ["best", "second", ""]


def _cells(md: str, first: str, strategy: str) -> list[str]:
    for line in md.splitlines():
        parts = [p.strip() for p in line.strip().strip("|").split("|")]
        if len(parts) > 2 and parts[1] == strategy and (not first or parts[0] == first):
            return parts
    raise AssertionError(f"no row {first!r}/{strategy!r} in\n{md}")


def test_table1_markdown_marks_per_track_and_aggregate():
    strategies = [ev.Strategy.fixed(0.3), ev.Strategy.fixed(0.5), ev.Strategy.fixed(0.7)]
    n3, n5, n7 = (s.name for s in strategies)
    rows = [
        # Laguna Seca: 0.3 best success, 0.5 and 0.7 tie for second; overtakes: 0.7 best, 0.3 second
        _row("LagunaSeca", n3, True, 200.0, 2.0, 5), _row("LagunaSeca", n3, True, 200.0, 2.0, 5),
        _row("LagunaSeca", n5, True, 200.0, 2.0, 6), _row("LagunaSeca", n5, False, 100.0, 1.0, 1),
        _row("LagunaSeca", n7, False, 150.0, 1.5, 9), _row("LagunaSeca", n7, True, 200.0, 2.0, 9),
        # Monza: 0.5 and 0.7 tie for the best success rate (no second place), 0.3 worst
        _row("Monza", n3, False, 10.0, 0.1, 0), _row("Monza", n5, True, 200.0, 1.0, 4),
        _row("Monza", n7, True, 100.0, 0.5, 2),
    ]
    md = ev.format_table1(rows, strategies, ["LagunaSeca", "Monza"])
    ls3 = _cells(md, "LagunaSeca (LS)", "γ = 0.30")
    ls5 = _cells(md, "", "γ = 0.50")  # first LS row holds the track name; next rows are blank
    assert ls3[2] == "**100.0**" and ls3[3] == "**400.0**" and ls3[5] == "<u>10</u>"
    assert ls5[2] == "<u>50.0</u>"
    lines = md.splitlines()
    ls7 = [p.strip() for p in lines[4].strip("|").split("|")]
    assert ls7[1] == "γ = 0.70" and ls7[2] == "<u>50.0</u>" and ls7[5] == "**18**" and ls7[3] == "<u>350.0</u>"
    mz5 = [p.strip() for p in lines[6].strip("|").split("|")]
    assert mz5[0] == "" and mz5[1] == "γ = 0.50" and mz5[2] == "**100.0**"
    assert _cells(md, "Monza", "γ = 0.30")[2] == "0.0"
    # aggregate block over both circuits: 0.3 -> 2/3, 0.5 -> 2/3, 0.7 -> 2/3 success; overtakes 10, 11, 20
    agg = _cells(md, "All circuits", "γ = 0.30")
    assert agg[2] == "**66.7**" and agg[5] == "10" and agg[-1] == "3"
    assert lines[-1].strip().strip("|").split("|")[5].strip() == "**20**"


def test_table2_ranks_over_all_rows():
    strategies = [ev.Strategy.fixed(0.5)]
    rows = [dict(_row("LagunaSeca", "gamma=0.50", False, 50.0, 0.5, 1), use_miqp=False),
            dict(_row("LagunaSeca", "gamma=0.50", True, 200.0, 2.0, 7), use_miqp=True)]
    md = ev.format_table2(rows, strategies)
    assert _cells(md, "w/o MIQP", "γ = 0.50")[2] == "<u>0.0</u>"
    assert _cells(md, "w/ MIQP", "γ = 0.50")[2] == "**100.0**"


def test_paper_comparison_lists_the_strategies_the_paper_has():
    strategies = [ev.Strategy.fixed(0.5), ev.Strategy.fixed(0.4)]  # the paper has no gamma = 0.40
    rows = [_row("Monza", "gamma=0.50", True, 200.0, 1.0, 2), _row("Monza", "gamma=0.50", False, 20.0, 0.1, 0),
            _row("Monza", "gamma=0.40", True, 200.0, 1.0, 2)]
    md = ev.paper_comparison(rows, strategies)
    assert md.splitlines()[2:] == ["| Monza | γ = 0.50 | 50.0 | 84.0 |"]
    assert ev.paper_comparison(rows[2:], strategies) == ""
