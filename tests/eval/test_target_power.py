"""The chance of a fixed gamma to meet a "within d points of the best fixed gamma" target, on cases known by hand."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

from sofar_agents.evaluation.target_power import format_target_power, target_power

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / "eval"))
import paired as paired_cli  # noqa: E402

from .episode_csv import write_episode_csv  # noqa: E402
from .test_paired import _rows  # noqa: E402


def test_a_dominating_gamma_always_meets_it_and_a_dominated_one_never():
    rows = _rows({"gamma=0.05": [1] * 20, "gamma=0.5": [1] * 10 + [0] * 10, "adaptive": [0] * 20})
    n, (low, high) = target_power({"S": rows}, episodes=40, resamples=2000)
    assert n == 20 and (low.strategy, high.strategy) == ("gamma=0.05", "gamma=0.5")  # adaptive is no fixed gamma
    assert low.pooled_success == 1.0 and low.probability == 1.0 and low.mean_shortfall == 0.0
    # gamma=0.5 reaches the best's 100 % only when all 40 draws are its successes: (1/2)^40
    assert high.pooled_success == 0.5 and high.probability == 0.0
    assert high.mean_shortfall == pytest.approx(-0.5, abs=0.01)


def test_one_episode_each_way_is_a_coin_flip_and_the_margin_counts_exactly():
    rows = _rows({"gamma=0.05": [1, 0], "gamma=0.15": [0, 1]})  # one resampled episode: A wins or B wins
    _, (a, b) = target_power({"S": rows}, episodes=1, resamples=20000, seed=3)
    assert a.probability == pytest.approx(0.5, abs=0.015) and a.probability + b.probability == pytest.approx(1.0)
    assert a.shortfall_p10 == -1.0
    # 50 episodes, 1 of them lost by gamma=0.05 only: its shortfall is 2 points per draw of that episode; a margin
    # of exactly 2 points is met unless it is drawn twice or more: (49/50)^50 + (49/50)^49 = 0.736
    rows = _rows({"gamma=0.05": [0] + [1] * 49, "gamma=0.15": [1] * 50})
    _, (a, _) = target_power({"S": rows}, episodes=50, margin=0.02, resamples=4000)
    assert a.probability == pytest.approx(0.736, abs=0.03)
    _, (a, _) = target_power({"S": rows}, episodes=1, margin=0.0, resamples=20000, seed=1)
    assert a.probability == pytest.approx(49 / 50, abs=0.005)
    text = format_target_power(50, [a], 1, 0.0, 20000)
    assert "| gamma=0.05 | 98.0 % |" in text


@pytest.mark.parametrize("kwargs, rows, match", [
    ({"episodes": 0}, {"gamma=0.05": [1], "gamma=0.5": [1]}, "episodes and resamples"),
    ({"margin": -0.01}, {"gamma=0.05": [1], "gamma=0.5": [1]}, "margin >= 0"),
    ({"margin": float("nan")}, {"gamma=0.05": [1], "gamma=0.5": [1]}, "margin >= 0"),
    ({}, {"gamma=0.05": [1], "adaptive": [1]}, "best of several fixed gammas"),
])
def test_bad_input_is_named(kwargs, rows, match):
    with pytest.raises(ValueError, match=match):
        target_power({"S": _rows(rows)}, **kwargs)


def test_fixed_gammas_without_a_shared_episode_are_refused():
    rows = [r for r in _rows({"gamma=0.05": [1, 1], "gamma=0.5": [1, 1]})
            if (r["strategy"], r["seed"]) in (("gamma=0.05", 0), ("gamma=0.5", 1))]
    with pytest.raises(ValueError, match="share no episode"):
        target_power({"S": rows})


def test_the_command_line(tmp_path, capsys):
    path = tmp_path / "set" / "table1_episodes.csv"
    write_episode_csv(path, _rows({"gamma=0.05": [1] * 10, "gamma=0.5": [1] * 5 + [0] * 5}))
    assert paired_cli.main(["--target-power", "10", str(path)]) == 0
    out = capsys.readouterr().out
    assert "| gamma=0.05 | 100.0 % | 1.00 |" in out and "10 episodes" in out
    assert paired_cli.main(["--target-power", "10", "--pareto", str(path)]) == 2
    assert "--target-power goes with neither" in capsys.readouterr().err
