"""The Pareto view: fronts, hypervolume (pymoo) against hand computations, preferences, the script's quick mode."""

import json

import numpy as np
import pytest

from sofar_agents import default_policy_path
from sofar_agents import evaluation as ev
from sofar_agents.evaluation.pareto import ParetoPoint, plot_fronts


def test_hypervolume_of_a_staircase_equals_the_hand_computed_area():
    # the union of [0,1]x[0,3], [0,2]x[0,2], [0,3]x[0,1]: 1*3 + 1*2 + 1*1
    pts = np.array([[1.0, 3.0], [2.0, 2.0], [3.0, 1.0]])
    assert ev.hypervolume(pts) == pytest.approx(6.0)
    # a dominated point adds nothing; a point not above the reference counts for nothing
    assert ev.hypervolume(np.vstack([pts, [[1.5, 1.5], [-1.0, 5.0]]])) == pytest.approx(6.0)
    # another reference point shifts the area: [1,2]x[1,2] + [1,3]x[1,...]
    assert ev.hypervolume(pts, reference=(1.0, 1.0)) == pytest.approx(1.0 * 1.0)
    assert ev.hypervolume(np.zeros((0, 2))) == 0.0


def test_pareto_front_keeps_the_non_dominated_points_sorted():
    v = np.array([[50.0, 10.0], [90.0, 5.0], [60.0, 4.0], [90.0, 5.0], [40.0, 12.0], [40.0, 11.0]])
    assert ev.pareto_front(v).tolist() == [4, 0, 1]


def test_preference_family_is_a_simplex_path():
    prefs = ev.preference_family([0.0, 0.45, 0.9])
    assert all(len(p) == 5 and sum(p) == pytest.approx(1.0) for p in prefs)
    assert [p[0] for p in prefs] == [0.0, 0.45, 0.9]
    assert [p[1] for p in prefs] == pytest.approx([0.9, 0.45, 0.0])
    for bad in ([0.95], [-0.1], [float("nan")]):
        with pytest.raises(ValueError, match="safety weight"):
            ev.preference_family(bad)


def test_strategy_points_aggregate_success_and_overtaking_rate():
    strategies = [ev.Strategy.fixed(0.3), ev.Strategy.fixed(0.7)]
    rows = [dict(strategy="gamma=0.30", success=True, sim_time=1800.0, overtakes=10),
            dict(strategy="gamma=0.30", success=False, sim_time=1800.0, overtakes=20),
            dict(strategy="gamma=0.70", success=True, sim_time=360.0, overtakes=3)]
    pts = ev.strategy_points(rows, strategies)
    assert [(p.name, p.success, p.overtakes_per_hour, p.episodes) for p in pts] == [
        ("gamma=0.30", 50.0, 30.0, 2), ("gamma=0.70", 100.0, 30.0, 1)]


def test_an_sb3_policy_is_its_own_family(tmp_path):
    zip_path = tmp_path / "ppo.zip"
    zip_path.write_bytes(b"not read here")
    strategies = ev.pareto_strategies(None, [], [0.3], sb3=zip_path)
    assert [s.name for s in strategies] == ["gamma=0.30", "PPO (SB3)"]
    rows = [dict(strategy="gamma=0.30", success=True, sim_time=3600.0, overtakes=10),
            dict(strategy="PPO (SB3)", success=False, sim_time=3600.0, overtakes=40)]
    assert [p.family for p in ev.strategy_points(rows, strategies)] == ["fixed", "baseline"]


def test_a_policy_strategy_takes_a_preference_it_can_use():
    path = default_policy_path()
    pref = ev.preference_family([0.5])[0]
    strat = ev.Strategy.adaptive(path, name="pasta w", preference=pref)
    policy = strat.build()
    assert policy.preference.tolist() == pytest.approx(pref)
    with pytest.raises(ValueError):
        ev.Strategy.adaptive(path, name="short", preference=(1.0, 0.0))  # five objectives expected
    with pytest.raises(ValueError, match="only a policy"):
        ev.Strategy(name="x", kind="fixed", gamma=0.5, preference=pref)


def test_plot_fronts_writes_a_png(tmp_path):
    pts = [ParetoPoint("a", "fixed", 90.0, 10.0, 5), ParetoPoint("b", "fixed", 80.0, 20.0, 5),
           ParetoPoint("p", "policy", 95.0, 15.0, 5, (0.5, 0.4, 0.1 / 3, 0.1 / 3, 0.1 / 3))]
    out = plot_fronts(pts, tmp_path / "f.png")
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_pareto_script_quick_mode(tmp_path, monkeypatch):
    import importlib.util
    from pathlib import Path

    spec = importlib.util.spec_from_file_location("pareto_cli", Path(__file__).parents[2] / "eval" / "pareto.py")
    cli = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(cli)
    out = tmp_path / "q"
    code = cli.main(["--quick", "--duration", "3", "--workers", "1", "--no-progress", "--out", str(out)])
    assert code == 0
    data = json.loads((out / "pareto.json").read_text())
    names = [p["name"] for p in data["points"]]
    assert names[:2] == ["gamma=0.30", "gamma=0.70"] and len(names) == 4  # 2 gammas + 2 preferences
    assert set(data["hypervolume"]) == {"fixed", "policy"}
    assert (out / "pareto.png").exists() and "hypervolume" in (out / "pareto.md").read_text()
    # resumed: nothing is run again
    assert cli.main(["--quick", "--duration", "3", "--workers", "1", "--no-progress", "--out", str(out)]) == 0
    assert cli.main(["--quick", "--safety-weights", "2", "--out", str(out)]) == 2


def _write_front(path, seeds, *, config_hash="abc123", mean_gamma_of_policy=0.3):
    """A pareto_episodes.csv with gamma=0.05 (always succeeds, 1 overtake), gamma=0.50 (fails on odd seeds,
    3 overtakes) and the policy at one preference (succeeds, 2 overtakes, its mean gamma given), 360 s each."""
    import csv

    extra = {"laps": 1.0, "collision": False, "off_track": False, "slack_steps": 0, "steps": 3600,
             "mpc_failures": 0, "miqp_failures": 0, "wall_time": 1.0, "episode": 0, "use_miqp": True,
             "duration": 360.0, "policy_id": "", "stack": "sofar-6", "config_hash": config_hash}
    rows = []
    for seed in seeds:
        for strategy, ok, ovt, gamma in (("gamma=0.05", True, 1, 0.05), ("gamma=0.50", seed % 2 == 0, 3, 0.5),
                                         ("pasta w=0.9/0/0.0333/0.0333/0.0333", True, 2, mean_gamma_of_policy)):
            rows.append({"track": "Monza", "strategy": strategy, "rho": 0.5, "seed": seed, "success": ok,
                         "sim_time": 360.0, "overtakes": ovt, "mean_gamma": gamma, **extra})
    with path.open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    return path


def test_pooled_seed_sets_are_one_front_over_all_their_episodes(tmp_path):
    a = _write_front(tmp_path / "a.csv", [0, 1], mean_gamma_of_policy=0.2)
    b = _write_front(tmp_path / "b.csv", [2, 3, 4, 5], mean_gamma_of_policy=0.5)
    points, hv, gamma, md = ev.pooled_pareto([a, b])
    by_name = {p.name: p for p in points}
    assert by_name["gamma=0.50"].success == pytest.approx(50.0) and by_name["gamma=0.50"].episodes == 6
    assert by_name["gamma=0.05"].overtakes_per_hour == pytest.approx(10.0)  # 6 overtakes in 6 x 360 s
    policy = by_name["pasta w=0.9/0/0.0333/0.0333/0.0333"]
    assert policy.family == "policy" and policy.preference == pytest.approx((0.9, 0.0, 0.0333, 0.0333, 0.0333))
    # fixed front: (100 %, 10 /h) and (50 %, 30 /h): 100 x 10 + 50 x 20 = 2000; the policy (100 %, 20 /h): 2000
    assert hv["fixed"] == pytest.approx(2000.0) and hv["policy"] == pytest.approx(2000.0)
    mean, sd = gamma["pasta w=0.9/0/0.0333/0.0333/0.0333"]
    assert mean == pytest.approx((2 * 0.2 + 4 * 0.5) / 6) and sd > 0.1
    assert "seed sets pooled" in md and "| gamma=0.50 | - | 50.0 | 30.0 | 6 | * |" in md


@pytest.mark.parametrize("case, message", [
    ("one file", "at least two"),
    ("same seeds twice", "is in two of the files"),
    ("two hashes", "2 configurations"),
    ("missing file", "no such CSV"),
])
def test_pooling_refuses_what_is_not_one_front(tmp_path, case, message):
    a = _write_front(tmp_path / "a.csv", [0, 1])
    other = {"one file": lambda: None, "same seeds twice": lambda: _write_front(tmp_path / "b.csv", [1, 2]),
             "two hashes": lambda: _write_front(tmp_path / "b.csv", [2, 3], config_hash="def456"),
             "missing file": lambda: tmp_path / "nope.csv"}[case]()
    with pytest.raises(ValueError, match=message):
        ev.pooled_pareto([a] if other is None else [a, other])


def test_pareto_script_pools_without_running(tmp_path, capsys):
    import importlib.util
    from pathlib import Path

    spec = importlib.util.spec_from_file_location("pareto_cli", Path(__file__).parents[2] / "eval" / "pareto.py")
    cli = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(cli)
    a, b = _write_front(tmp_path / "a.csv", [0]), _write_front(tmp_path / "b.csv", [1])
    assert cli.main(["--pool", str(a), str(b), "--out", str(tmp_path / "out")]) == 0
    assert (tmp_path / "out" / "pareto_pooled.md").read_text().startswith("# Pareto view, seed sets pooled")
    assert cli.main(["--pool", str(a), str(b)]) == 2 and "--pool needs --out" in capsys.readouterr().err
    assert cli.main(["--pool", str(a), "--out", str(tmp_path / "x")]) == 2
    assert not (tmp_path / "x").exists()
