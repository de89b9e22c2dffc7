"""eval/safety_signals.py: per-step means by hand, one short episode, bad input named."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / "eval"))
import safety_signals as script  # noqa: E402


def _row(gamma, steps, failed, slack, depth, inside, near):
    return {"track": "X", "rho": 0.5, "seed": 1, "gamma": gamma, "steps": steps, "failed": failed,
            "slack_sum": slack, "depth_sum": depth, "inside_steps": inside, "near_steps": near}


def test_per_step_means_pool_the_episodes_of_a_gamma():
    rows = [_row(0.05, 100, 1, 1.0, 2.0, 10, 0), _row(0.05, 300, 0, 3.0, 0.0, 10, 40), _row(0.5, 50, 0, 0.0, 0.5, 5, 5)]
    text = script.summary(rows, 8.0)
    assert "| 0.05 | 2 | 1 | 0.01000 | 0.00500 | 5.00 % | 10.00 % |" in text
    assert "| 0.5 | 1 | 0 | 0.00000 | 0.01000 | 10.00 % | 10.00 % |" in text


def test_one_short_episode_counts_its_steps():
    row = script.run_episode(("Monza", 0.5, 3, 0.3, "interactive", {}, 0.5, 8.0))
    assert row["steps"] == 5 and row["failed"] == 0 and row["gamma"] == 0.3
    assert 0 <= row["inside_steps"] <= 5 and row["slack_sum"] >= 0.0 and row["depth_sum"] >= 0.0
    assert len(row["config_hash"]) == 12


@pytest.mark.parametrize("argv, message", [
    (["--env-kwargs", "[1]"], "--env-kwargs"),
    (["--env-kwargs", "{bad"], "--env-kwargs"),
])
def test_bad_env_kwargs_are_named(tmp_path, capsys, argv, message):
    assert script.main([*argv, "--out", str(tmp_path)]) == 2
    assert message in capsys.readouterr().err and not any(tmp_path.iterdir())


@pytest.mark.parametrize("gamma", ["0", "1.5", "nan"])
def test_gammas_outside_the_range_are_usage_errors(tmp_path, gamma):
    with pytest.raises(SystemExit):
        script.parse_args(["--gammas", gamma, "--out", str(tmp_path)])
