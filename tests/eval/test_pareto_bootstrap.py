"""The paired, stratified bootstrap of a difference of hypervolumes (``eval/pareto.py --bootstrap``)."""

from __future__ import annotations

import csv
import importlib.util
from pathlib import Path

import numpy as np
import pytest

from sofar_agents.evaluation.pareto_bootstrap import bootstrap_hypervolume, bootstrap_markdown

POLICY_SAFE = "pasta w=0.9/0/0.0333/0.0333/0.0333"
POLICY_BOLD = "pasta w=0.1/0.8/0.0333/0.0333/0.0333"


def _rows(outcomes, cells=(("Monza", 0.5),), episodes=8) -> list[dict]:
    """Rows of every strategy in ``outcomes`` (name -> function (cell index, episode) -> (success, overtakes)), 360 s
    per episode, ``episodes`` per cell."""
    rows = []
    for c, (track, rho) in enumerate(cells):
        for e in range(episodes):
            for name, outcome in outcomes.items():
                ok, ovt = outcome(c, e)
                rows.append({"track": track, "rho": rho, "seed": 1000 * c + e, "strategy": name, "success": int(ok),
                             "overtakes": ovt, "sim_time": 360.0})
    return rows


def _luck(c, e) -> bool:
    return (7 * e + 3 * c) % 5 < 3  # episodes differ in luck: 3 in 5 succeed


BASE = {"gamma=0.05": lambda c, e: (True, 1), "gamma=0.50": lambda c, e: (_luck(c, e), 3 + e % 2)}


def test_outcomes_without_spread_give_the_observed_difference_on_every_draw():
    rows = _rows({**BASE, "gamma=0.50": lambda c, e: (e % 2 == 0, 3), POLICY_SAFE: lambda c, e: (True, 2)}, episodes=2)
    # every draw of a 2-episode cell: 0, 1 or 2 successes of gamma 0.50, so its point moves; the policy's does not
    result = bootstrap_hypervolume(rows, resamples=200)
    # observed: fixed front (100 %, 10 /h), (50 %, 30 /h) = 100 x 10 + 50 x 20 = 2000; policy (100 %, 20 /h) = 2000
    assert result.observed == pytest.approx((2000.0, 2000.0)) and result.difference == pytest.approx(0.0)
    const = _rows({"gamma=0.05": lambda c, e: (True, 1), POLICY_SAFE: lambda c, e: (True, 2)})
    fixed = bootstrap_hypervolume(const, resamples=200)
    assert np.all(fixed.differences == pytest.approx(1000.0)) and fixed.interval() == pytest.approx((1000.0, 1000.0))


def test_a_copy_of_the_fixed_family_differs_by_zero_on_every_draw():
    rows = _rows({**BASE, POLICY_SAFE: BASE["gamma=0.05"], POLICY_BOLD: BASE["gamma=0.50"]})
    result = bootstrap_hypervolume(rows, resamples=300)
    assert np.all(result.differences == 0.0) and result.share_b_at_least_a == 1.0


def test_the_draws_are_paired_so_a_policy_better_in_every_episode_wins_every_draw():
    better = {POLICY_SAFE: lambda c, e: (True, 2), POLICY_BOLD: lambda c, e: (_luck(c, e), 4 + e % 2)}
    rows = _rows({**BASE, **better}, cells=(("Monza", 0.5), ("Kentucky", 0.1)))
    result = bootstrap_hypervolume(rows, resamples=500)
    lo, hi = result.interval()
    assert result.share_b_at_least_a == 1.0 and 0.0 < lo <= result.difference <= hi
    assert result.episodes == 16 and result.cells == 2


def test_the_draws_keep_each_cell_so_a_cell_level_difference_is_not_noise():
    # gamma 0.50 succeeds in every Monza episode and in no Kentucky one: 50 % on every stratified draw
    rows = _rows({"gamma=0.50": lambda c, e: (c == 0, 3), POLICY_SAFE: lambda c, e: (True, 1)},
                 cells=(("Monza", 0.5), ("Kentucky", 0.1)))
    result = bootstrap_hypervolume(rows, resamples=300)
    assert np.all(result.differences == pytest.approx(100.0 * 10.0 - 50.0 * 30.0))


def test_the_same_seed_draws_the_same_and_another_seed_other_draws():
    rows = _rows({**BASE, POLICY_SAFE: lambda c, e: (_luck(c, e + 1), 2)})
    a, b = bootstrap_hypervolume(rows, resamples=200, seed=3), bootstrap_hypervolume(rows, resamples=200, seed=3)
    assert np.array_equal(a.differences, b.differences)
    assert not np.array_equal(a.differences, bootstrap_hypervolume(rows, resamples=200, seed=4).differences)
    md = bootstrap_markdown(a, ["x.csv"])
    assert "paired bootstrap" in md and "share of draws with policy >= fixed" in md and "generator seed 3" in md


@pytest.mark.parametrize("case, kwargs, message", [
    ("no policy strategy", {}, "no strategy of family 'policy'"),
    ("too few draws", {"resamples": 99}, "resamples must be an integer >= 100"),
    ("a fractional number of draws", {"resamples": 150.5}, "resamples must be an integer"),
    ("one family twice", {"families": ("fixed", "fixed")}, "two different names"),
    ("an episode missing", {}, "did not run the same episodes"),
    ("an episode twice", {}, "ran episode"),
])
def test_bad_input_is_refused_by_name(case, kwargs, message):
    rows = _rows({**BASE, POLICY_SAFE: lambda c, e: (True, 2)})
    if case == "no policy strategy":
        rows = [r for r in rows if r["strategy"] != POLICY_SAFE]
    elif case == "an episode missing":
        rows = rows[:-1]
    elif case == "an episode twice":
        rows = rows + [dict(rows[0])]
    with pytest.raises(ValueError, match=message):
        bootstrap_hypervolume(rows, **kwargs)


def _cli():
    spec = importlib.util.spec_from_file_location("pareto_cli", Path(__file__).parents[2] / "eval" / "pareto.py")
    cli = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(cli)
    return cli


def test_the_script_writes_the_report_and_refuses_bad_calls(tmp_path, capsys):
    path = tmp_path / "pareto_episodes.csv"
    extra = {"laps": 1.0, "collision": False, "off_track": False, "slack_steps": 0, "steps": 3600, "mean_gamma": 0.1,
             "mpc_failures": 0, "miqp_failures": 0, "wall_time": 1.0, "episode": 0, "use_miqp": True,
             "duration": 360.0, "policy_id": "", "stack": "sofar-6", "config_hash": "abc123"}
    rows = [{**r, **extra} for r in _rows({**BASE, POLICY_SAFE: lambda c, e: (True, 2)})]
    with path.open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    cli = _cli()
    assert cli.main(["--bootstrap", str(path), "--out", str(tmp_path / "out"), "--resamples", "150"]) == 0
    assert (tmp_path / "out" / "hv_bootstrap.md").read_text().startswith("# Hypervolume of the policy front")
    assert cli.main(["--bootstrap", str(path)]) == 2 and "--bootstrap needs --out" in capsys.readouterr().err
    assert cli.main(["--bootstrap", str(path), "--pool", str(path), "--out", str(tmp_path / "y")]) == 2
    assert cli.main(["--bootstrap", str(tmp_path / "nope.csv"), "--out", str(tmp_path / "z")]) == 2
    assert not (tmp_path / "y").exists() and not (tmp_path / "z").exists()
