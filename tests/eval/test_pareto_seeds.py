"""A training recipe's front over its training seeds (``eval/pareto.py --training-seeds``)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from sofar_agents.evaluation.pareto_bootstrap import bootstrap_hypervolume
from sofar_agents.evaluation.pareto_seeds import training_seed_fronts, training_seeds_markdown

from .episode_csv import write_episode_csv
from .test_pareto_bootstrap import _cli

SAFE = "pasta w=0.9/0/0.0333/0.0333/0.0333"
BOLD = "pasta w=0.1/0.8/0.0333/0.0333/0.0333"
FIXED = {"gamma=0.05": lambda c, e: (True, 1), "gamma=0.50": lambda c, e: (e % 2 == 0, 3)}


def _rows(policy: dict, policy_id: str, cells=(("Monza", 0.5),), episodes=2, config_hash="abc") -> list[dict]:
    """The rows of one Pareto file: the fixed gammas of ``FIXED`` and the policy strategies of ``policy``
    (name -> function (cell, episode) -> (success, overtakes)), 360 s an episode, mean gamma 0.1."""
    rows = []
    for c, (track, rho) in enumerate(cells):
        for e in range(episodes):
            for name, outcome in {**FIXED, **policy}.items():
                ok, ovt = outcome(c, e)
                rows.append({"track": track, "rho": rho, "seed": 1000 * c + e, "strategy": name, "success": int(ok),
                             "overtakes": ovt, "sim_time": 360.0, "mean_gamma": 0.1, "config_hash": config_hash,
                             "policy_id": "" if name.startswith("gamma=") else policy_id})
    return rows


def _seed_a():
    return _rows({SAFE: lambda c, e: (True, 2), BOLD: lambda c, e: (e == 0, 4)}, "aaa")


def _seed_b():
    return _rows({SAFE: lambda c, e: (e == 0, 2), BOLD: lambda c, e: (e == 0, 6)}, "bbb")


def test_the_recipe_s_difference_and_the_pooled_front_are_computed_by_hand():
    result = training_seed_fronts({"a": _seed_a(), "b": _seed_b()}, resamples=200)
    # fixed: (100 %, 10 /h), (50 %, 30 /h): 100 x 10 + 50 x 20 = 2000
    assert result.hv_fixed == pytest.approx(2000.0)
    # seed a: (100 %, 20 /h), (50 %, 40 /h): 100 x 20 + 50 x 20 = 3000; seed b: (50 %, 20), (50 %, 60): 50 x 60
    assert result.hv_seeds == pytest.approx((3000.0, 3000.0))
    assert result.difference == pytest.approx(1000.0) and result.relative(np.mean(result.hv_seeds)) == 0.5
    # pooled over the four episodes of each preference: SAFE (75 %, 20 /h), BOLD (50 %, 50 /h)
    pts = {p.name: (p.success, p.overtakes_per_hour, p.episodes) for p in result.pooled}
    assert pts == {SAFE: pytest.approx((75.0, 20.0, 4)), BOLD: pytest.approx((50.0, 50.0, 4))}
    assert result.hv_pooled == pytest.approx(75.0 * 20.0 + 50.0 * 30.0)
    assert result.episodes == 2 and result.cells == 1 and result.policy_ids == ("aaa", "bbb")


def test_two_copies_of_one_front_give_its_own_hypervolume_and_no_seed_spread():
    a, b = _seed_a(), [{**r, "policy_id": "ccc" if r["policy_id"] else ""} for r in _seed_a()]
    result = training_seed_fronts({"a": a, "b": b}, resamples=300)
    assert result.hv_pooled == pytest.approx(result.hv_seeds[0]) == pytest.approx(result.hv_seeds[1])
    single = bootstrap_hypervolume(a, resamples=300)  # its episode draws: the same generator, the same order
    assert result.difference == pytest.approx(single.difference)
    assert np.allclose(result.diff_episodes, single.differences)
    # drawing the seeds changes nothing when they are the same policy twice
    assert np.allclose(result.diff_episodes, result.diff_seeds_episodes)


def test_drawing_the_seeds_widens_the_interval_when_the_seeds_differ():
    cells = (("Monza", 0.5), ("Kentucky", 0.1))
    good = _rows({SAFE: lambda c, e: (True, 2), BOLD: lambda c, e: (True, 5)}, "g", cells=cells, episodes=6)
    poor = _rows({SAFE: lambda c, e: (e % 3 == 0, 1), BOLD: lambda c, e: (e % 3 == 0, 2)}, "p", cells=cells,
                 episodes=6)
    result = training_seed_fronts({"g": good, "p": poor}, resamples=400, seed=1)
    lo_e, hi_e = result.interval(result.diff_episodes)
    lo_s, hi_s = result.interval(result.diff_seeds_episodes)
    assert hi_s - lo_s > hi_e - lo_e
    # draws of the good seed twice lie above every draw of the mixture, of the poor one twice below
    assert result.diff_seeds_episodes.max() > result.diff_episodes.max()
    assert result.diff_seeds_episodes.min() < result.diff_episodes.min()
    again = training_seed_fronts({"g": good, "p": poor}, resamples=400, seed=1)
    assert np.array_equal(again.diff_seeds_episodes, result.diff_seeds_episodes)


def _without_episode(rows):
    return [r for r in rows if not (r["strategy"] == BOLD and r["seed"] == 1)]


@pytest.mark.parametrize("files, match", [
    ({"a": _seed_a()}, "at least two"),
    ({"a": _seed_a(), "b": []}, "no episode rows"),
    ({"a": _seed_a(), "b": [r for r in _seed_b() if r["strategy"].startswith("gamma=")]}, "fixed-gamma rows and"),
    ({"a": _seed_a(), "b": [{**r, "overtakes": 9} if r["strategy"] == "gamma=0.05" else r for r in _seed_b()]},
     "fixed-gamma rows of b differ"),
    ({"a": _seed_a(), "b": [r for r in _seed_b() if r["strategy"] != SAFE]}, "preferences"),
    ({"a": _seed_a(), "b": _seed_a()}, "one policy is in two files"),
    ({"a": _seed_a(), "b": [{**r, "policy_id": "x" if r["strategy"] == SAFE else r["policy_id"]}
                            for r in _seed_b()]}, "one policy_id"),
    ({"a": _seed_a(), "b": [{**r, "config_hash": "zzz"} if r["strategy"] == SAFE else r for r in _seed_b()]},
     "one configuration hash"),
    ({"a": _seed_a(), "b": _without_episode(_seed_b())}, "did not run the same episodes"),
])
def test_files_that_do_not_make_one_recipe_s_seeds_are_refused(files, match):
    with pytest.raises(ValueError, match=match):
        training_seed_fronts(files, resamples=100)


def test_too_few_draws_are_refused():
    with pytest.raises(ValueError, match="resamples"):
        training_seed_fronts({"a": _seed_a(), "b": _seed_b()}, resamples=10)


def _write(path: Path, rows: list[dict]) -> str:
    write_episode_csv(path, [{**r, "use_miqp": 1} for r in rows])
    return str(path)


def test_the_command_writes_the_report_and_refuses_bad_files(tmp_path, capsys):
    a = _write(tmp_path / "a" / "pareto_episodes.csv", _seed_a())
    b = _write(tmp_path / "b" / "pareto_episodes.csv", _seed_b())
    cli = _cli()
    assert cli.main(["--training-seeds", a, b, "--out", str(tmp_path / "out"), "--resamples", "100"]) == 0
    md = (tmp_path / "out" / "training_seeds.md").read_text()
    assert "**+50.0 %**" in md and "policy aaa" in md and md == training_seeds_markdown(
        training_seed_fronts({str(tmp_path / "a"): _seed_a(), str(tmp_path / "b"): _seed_b()}, resamples=100))
    assert cli.main(["--training-seeds", a, a, "--out", str(tmp_path / "x")]) == 2
    assert cli.main(["--training-seeds", a, b]) == 2
    assert cli.main(["--training-seeds", a, b, "--pool", a, b, "--out", str(tmp_path / "x")]) == 2
    assert not (tmp_path / "x").exists()
    assert "error" in capsys.readouterr().err
