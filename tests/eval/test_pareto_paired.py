"""Paired tests of a Pareto sweep's points: which fixed gammas a point is read against, and the two tests."""

from __future__ import annotations

import csv

import pytest

from sofar_agents.evaluation.pareto_paired import compare_points, format_pareto_paired, pareto_pairs


def _rows() -> list[dict]:
    rows = []
    for seed in range(10):
        for strategy, gamma, win, ovt in (("gamma=0.05", 0.05, True, 1), ("gamma=0.50", 0.5, seed < 6, 3),
                                          ("pasta w=0.9", 0.07, seed < 9, 1), ("pasta w=0.1", 0.42, seed < 6, 4)):
            rows.append({"track": "Monza", "rho": 0.5, "seed": seed, "use_miqp": True, "strategy": strategy,
                         "success": win, "overtakes": ovt + (seed % 2 if strategy == "pasta w=0.1" else 0),
                         "sim_time": 200.0, "mean_gamma": gamma})
    return rows


def test_each_point_is_read_against_its_nearest_and_the_best_fixed_gamma():
    assert pareto_pairs(_rows()) == [("pasta w=0.9", pytest.approx(0.07), ["gamma=0.05"]),
                                     ("pasta w=0.1", pytest.approx(0.42), ["gamma=0.50", "gamma=0.05"])]


def test_success_and_overtaking_rate_are_paired_by_episode():
    _, success, rates = compare_points(_rows())
    first = success[0]  # pasta w=0.9 against gamma=0.05: 9 against 10 wins, the one loss its own
    assert (first.a, first.b, first.n, first.a_only, first.b_only) == ("pasta w=0.9", "gamma=0.05", 10, 0, 1)
    assert first.p_value == 1.0
    bold = rates[1]  # pasta w=0.1 against gamma=0.50: 4 or 5 against 3 overtakes per 200 s, in every episode
    assert bold.n == 10 and bold.rate_b == pytest.approx(3 * 18.0)
    assert bold.rate_a == pytest.approx(4.5 * 18.0) and bold.median_difference == pytest.approx(1.5 * 18.0)
    assert bold.p_value < 0.01
    same = rates[0]  # identical overtakes: no difference to test
    assert same.median_difference == 0.0 and same.p_value == 1.0


def test_extra_strategies_are_compared_with_every_point_once():
    pairs = pareto_pairs(_rows(), extra=["gamma=0.50", "pasta w=0.9"])
    assert pairs[0][2] == ["gamma=0.05", "gamma=0.50"]  # a point is not compared with itself
    assert pairs[1][2] == ["gamma=0.50", "gamma=0.05", "pasta w=0.9"]
    with pytest.raises(ValueError, match="no episodes of"):
        pareto_pairs(_rows(), extra=["gamma=0.70"])


def test_rows_without_a_fixed_gamma_are_refused():
    with pytest.raises(ValueError, match="no fixed gamma"):
        pareto_pairs([r for r in _rows() if not r["strategy"].startswith("gamma=")])


def test_the_script_writes_the_tables(tmp_path, capsys):
    import importlib.util
    from pathlib import Path

    path = tmp_path / "pareto_episodes.csv"
    extra = {"laps": 1.0, "collision": False, "off_track": False, "slack_steps": 0, "steps": 2000,
             "mpc_failures": 0, "miqp_failures": 0, "wall_time": 1.0, "episode": 0, "duration": 200.0,
             "policy_id": ""}
    rows = [{**r, **extra} for r in _rows()]
    with path.open("w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    spec = importlib.util.spec_from_file_location("paired_script", Path(__file__).parents[2] / "eval" / "paired.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    out = tmp_path / "paired.md"
    assert mod.main(["--pareto", str(path), "--out", str(out)]) == 0
    text = out.read_text()
    assert "exact McNemar" in text and "Wilcoxon" in text and "| pasta w=0.1 | 0.420 | gamma=0.50, gamma=0.05 |" in text
    assert mod.main(["--pareto", str(path), str(path)]) == 2  # the same file twice
    other = tmp_path / "set2" / "pareto_episodes.csv"
    other.parent.mkdir()
    other.write_text(path.read_text())
    assert mod.main(["--pareto", str(path), str(other)]) == 2  # the same episodes twice
    shifted = [{**r, "seed": r["seed"] + 100} for r in rows]
    with other.open("w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(shifted[0]))
        w.writeheader()
        w.writerows(shifted)
    pooled = tmp_path / "pooled.md"
    assert mod.main(["--pareto", str(path), str(other), "--out", str(pooled)]) == 0
    assert "| pasta w=0.9 | gamma=0.05 | 20 |" in pooled.read_text()  # 10 + 10 paired episodes
    assert format_pareto_paired(rows).count("pasta w=0.1 | gamma=") == 4
