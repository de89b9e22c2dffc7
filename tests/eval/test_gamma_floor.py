"""A policy's gamma floored in chosen states: the rule by hand, bad settings, the applied gamma in a real episode,
and a study whose floored rows differ from the plain policy's only where the floor acts."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sofar_agents.evaluation.gamma_floor import FloorGamma, GammaFloor, floor_strategies, run_floor_study
from sofar_agents.evaluation.results import read_episode_csv, read_trace_csv

POLICY = "sofar_agents/checkpoints/pasta_morl_interactive_sofar13.json"
PREFERENCE = (0.1, 0.8, 0.1 / 3, 0.1 / 3, 0.1 / 3)


@pytest.mark.parametrize(("where", "nearest", "applies"), [
    ("always", 5.0, True), ("always", math.inf, True),
    ("far", 5.0, False), ("far", 20.0, True), ("far", math.inf, True), ("far", math.nan, True),
    ("near", 5.0, True), ("near", 19.99, True), ("near", 20.0, False), ("near", math.inf, False),
])
def test_where_the_floor_holds(where, nearest, applies):
    assert GammaFloor(0.15, where, 20.0).applies(nearest) is applies


@pytest.mark.parametrize(("kwargs", "names"), [
    ({"floor": 0.01}, "floor"), ({"floor": 1.5}, "floor"), ({"floor": math.nan}, "floor"), ({"floor": "0.2"}, "floor"),
    ({"floor": 0.2, "where": "behind"}, "where"), ({"floor": 0.2, "radius": 0.0}, "radius"),
    ({"floor": 0.2, "radius": math.inf}, "radius"), ({"floor": 0.2, "radius": -3.0}, "radius"),
])
def test_bad_floors_are_refused_naming_the_field(kwargs, names):
    with pytest.raises(ValueError, match=names):
        GammaFloor(**kwargs)


def test_labels_and_names():
    assert GammaFloor(0.15).label == "floor 0.15"
    assert GammaFloor(0.15, "far", 20).label == "floor 0.15 beyond 20 m"
    assert GammaFloor(0.3, "near", 12.5).label == "floor 0.3 within 12.5 m"
    strategies, named = floor_strategies(POLICY, PREFERENCE, [GammaFloor(0.15, "far")], gammas=[0.05])
    assert [s.name for s in strategies] == ["gamma=0.05", "pasta w=0.1/0.8/0.0333/0.0333/0.0333",
                                            "pasta w=0.1/0.8/0.0333/0.0333/0.0333 floor 0.15 beyond 20 m"]
    assert named == {strategies[2].name: GammaFloor(0.15, "far")}
    with pytest.raises(ValueError, match="share the name"):
        floor_strategies(POLICY, PREFERENCE, [GammaFloor(0.15), GammaFloor(0.15)])


def _applied_gammas(spec: GammaFloor, steps: int = 30) -> tuple[np.ndarray, np.ndarray]:
    from sofar_agents.evaluation.episode import make_env

    env = FloorGamma(make_env("LagunaSeca", stack="sofar", scenario="interactive", duration=10.0), spec)
    try:
        _, info = env.reset(seed=3, options={"rho": 0.5, "n_opponents": 8})
        nearest, gammas = [info["nearest_opponent_m"]], []
        for _ in range(steps):
            _, _, terminated, truncated, info = env.step(np.array([0.05], dtype=np.float32))
            gammas.append(info["gamma"])
            nearest.append(info["nearest_opponent_m"])
            if terminated or truncated:
                break
    finally:
        env.close()
    return np.asarray(gammas), np.asarray(nearest[:len(gammas)])


def test_the_environment_applies_the_floor_where_it_holds():
    gammas, _ = _applied_gammas(GammaFloor(0.2))
    assert np.allclose(gammas, 0.2)
    gammas, nearest = _applied_gammas(GammaFloor(0.2, "near", 80.0))  # the first car is 117 m ahead at the start
    near = nearest < 80.0  # the distance each decision was made at
    assert near.any() and (~near).any(), "the scene must have both kinds of step"
    assert np.allclose(gammas[near], 0.2) and np.allclose(gammas[~near], 0.05)


def test_a_study_resumes_and_floors_only_its_own_rows(tmp_path):
    floors = [GammaFloor(1.0, "near", 1e-3)]  # never near: the floored policy must drive exactly as the plain one
    kwargs = dict(gammas=[0.3], tracks=["LagunaSeca"], rhos=[0.5], episodes=1, base_seed=7, duration=4.0,
                  workers=1, progress=False, stack="sofar", scenario="interactive", n_opponents=8, trace=True)
    report = run_floor_study(POLICY, PREFERENCE, floors, tmp_path, **kwargs)
    assert report.stats.completed == 3 and report.stats.unfinished == 0
    rows = {r["strategy"]: r for r in read_episode_csv(tmp_path / "floor_episodes.csv")}
    plain = rows["pasta w=0.1/0.8/0.0333/0.0333/0.0333"]
    floored = rows["pasta w=0.1/0.8/0.0333/0.0333/0.0333 floor 1 within 0.001 m"]
    for col in ("overtakes", "mean_gamma", "sim_time", "success", "seed", "config_hash"):
        assert floored[col] == plain[col], col
    assert rows["gamma=0.30"]["mean_gamma"] == pytest.approx(0.3)
    text = report.path.read_text()
    assert text == report.markdown
    assert "| gamma=0.30 | 1 |" in text and "mean gamma, a car within 0.001 m" in text
    trace = read_trace_csv(tmp_path / "floor_trace.csv", "gamma=0.30")
    assert len(trace["gamma"]) == int(rows["gamma=0.30"]["steps"]) and np.allclose(trace["gamma"], 0.3)
    assert f"| {len(trace['gamma']):,} | - | 0.300 (100 %) | 0 % |" in text
    again = run_floor_study(POLICY, PREFERENCE, floors, tmp_path, **kwargs)
    assert again.stats.completed == 0 and again.stats.skipped == 3


@pytest.mark.parametrize(("extra", "message"), [
    ('safety_weights = [0.1, 0.9]\n', "one preference"),
    ('safety_weights = [0.1]\nwhere = ["behind"]\n', "where must be one of"),
    ('safety_weights = [0.1]\nwhere = []\n', "at least one place"),
    ('safety_weights = [0.1]\nfloor = 0.01\n', "floor must be a gamma"),
    ('safety_weights = [0.1]\nradius = -1.0\n', "radius must be"),
])
def test_a_bad_floor_manifest_is_refused_naming_the_file(tmp_path, extra, message):
    from sofar_agents.evaluation.manifest import load_manifest

    path = tmp_path / "bad_floor.toml"
    path.write_text(f'kind = "floor"\nout = "x"\npolicy = "{POLICY}"\n' + extra)
    with pytest.raises(ValueError, match=message) as err:
        load_manifest(path)
    assert "bad_floor" in str(err.value)


def test_a_floor_manifest_names_the_strategies_of_the_script(tmp_path):
    from pathlib import Path

    from sofar_agents.evaluation.manifest import episode_ids, load_manifest

    root = Path(__file__).resolve().parents[2]
    m = load_manifest(root / "experiments" / "interactive_dense_morl_floor_seed17300_sofar_13.toml")
    names = [s.name for s in m.strategies(root)]
    assert names == ["gamma=0.05", "gamma=0.15", "gamma=0.30", "gamma=0.50", "pasta w=0.1/0.8/0.0333/0.0333/0.0333",
                     "pasta w=0.1/0.8/0.0333/0.0333/0.0333 floor 0.15",
                     "pasta w=0.1/0.8/0.0333/0.0333/0.0333 floor 0.15 beyond 20 m",
                     "pasta w=0.1/0.8/0.0333/0.0333/0.0333 floor 0.15 within 20 m"]
    assert m.trace and m.csv_name == "floor_episodes.csv" and len(episode_ids(m, root)) == 8 * 40
