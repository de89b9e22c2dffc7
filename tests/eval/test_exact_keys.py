"""Resume keys and labels hold the exact settings: fixed gammas (and rhos, durations) that round alike do not
share rows, in the Table I sweep and in the multi-agent table, and the committed rows still read under their keys."""

from __future__ import annotations

from pathlib import Path

import pytest

from sofar_agents import evaluation as ev
from sofar_agents.evaluation import multi_agent as ma
from sofar_agents.evaluation import sweep
from sofar_agents.evaluation.interventions import Intervention
from sofar_agents.evaluation.protocol import exact_text, gamma_text

# (gamma, its name in the CSV, its label in the tables)
NAMES = [
    (0.05, "gamma=0.05", "γ = 0.05"),
    (0.3, "gamma=0.30", "γ = 0.30"),  # the committed files' names keep two decimals
    (0.95, "gamma=0.95", "γ = 0.95"),
    (1.0, "gamma=1.00", "γ = 1.00"),
    (0.054, "gamma=0.054", "γ = 0.054"),
    (0.075, "gamma=0.075", "γ = 0.075"),
    (0.1 + 0.2, "gamma=0.30000000000000004", "γ = 0.30000000000000004"),
]


@pytest.mark.parametrize(("gamma", "name", "label"), NAMES, ids=[n for _, n, _ in NAMES])
def test_a_fixed_strategy_is_named_by_its_exact_gamma(gamma: float, name: str, label: str) -> None:
    s = ev.Strategy.fixed(gamma)
    assert (s.name, s.label) == (name, label)
    assert float(gamma_text(gamma)) == gamma


@pytest.mark.parametrize("x", [0.3, 200.0, 60.0, 0.65, 0.30000001, 1e-7, 123456.5])
def test_exact_text_reads_back_to_the_same_float(x: float) -> None:
    assert float(exact_text(x)) == x
    assert exact_text(x) == f"{x:g}" or float(f"{x:g}") != x  # the short form whenever it is exact


def _result(task: ev.EpisodeTask) -> ev.EpisodeResult:
    return ev.EpisodeResult(track=task.track, strategy=task.strategy.name, rho=task.rho, seed=task.seed,
                            success=True, sim_time=1.0, laps=0.1, overtakes=0, collision=False, off_track=False,
                            slack_steps=0, steps=10, mean_gamma=float(task.strategy.gamma), mpc_failures=0,
                            miqp_failures=0, wall_time=0.0, episode=task.episode, use_miqp=task.use_miqp,
                            duration=task.duration, policy_id=task.strategy.policy_id, stack=task.stack,
                            scenario=task.scenario, config_hash=task.config_hash)


# (what the CSV holds: gamma, rho, duration; what is asked: gamma, rho, duration; is it taken from the CSV?)
SWEEP_CASES = [
    ((0.05, 0.3, 200.0), (0.05, 0.3, 200.0), True),
    ((0.05, 0.3, 200.0), (0.054, 0.3, 200.0), False),
    ((0.054, 0.3, 200.0), (0.054, 0.3, 200.0), True),
    ((0.07, 0.3, 200.0), (0.075, 0.3, 200.0), False),
    ((0.05, 0.3, 200.0), (0.05, 0.30000001, 200.0), False),
    ((0.05, 0.30000001, 200.0), (0.05, 0.30000001, 200.0), True),
    ((0.05, 0.3, 200.0), (0.05, 0.3, 200.0000001), False),
]


@pytest.mark.parametrize(("held", "asked", "taken"), SWEEP_CASES,
                         ids=[f"{h}->{a}" for h, a, _ in SWEEP_CASES])
def test_the_sweep_takes_from_the_csv_only_the_same_settings(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                             held: tuple, asked: tuple, taken: bool) -> None:
    csv_path = tmp_path / "table1_episodes.csv"

    def task(gamma: float, rho: float, duration: float) -> ev.EpisodeTask:
        return ev.table1_tasks([ev.Strategy.fixed(gamma)], ["Monza"], [rho], 1, duration=duration)[0]

    ran: list[ev.EpisodeTask] = []

    def fake_run(self, t: ev.EpisodeTask):  # no simulation: the resume logic is under test
        ran.append(t)
        return _result(t), []

    monkeypatch.setattr(sweep._EpisodeRunner, "run", fake_run)
    ev.run_sweep([task(*held)], csv_path, workers=1, progress=False)
    ran.clear()
    stats = ev.run_sweep([task(*asked)], csv_path, workers=1, progress=False)
    assert (stats.skipped, len(ran)) == ((1, 0) if taken else (0, 1))
    rows = ev.read_episode_csv(csv_path)
    assert len(rows) == (1 if taken else 2)
    assert {r["strategy"] for r in rows} == {ev.Strategy.fixed(held[0]).name, ev.Strategy.fixed(asked[0]).name}
    assert [(r["rho"], r["duration"]) for r in ev.select_rows(rows, [task(*asked)])] == [asked[1:]]


# (gamma and duration of the races in the CSV, those asked, taken from the CSV?)
RACE_CASES = [
    ((0.05, 200.0), (0.05, 200.0), True),
    ((0.05, 200.0), (0.054, 200.0), False),
    ((0.07, 200.0), (0.075, 200.0), False),
    ((0.05, 200.0), (0.05, 200.0000001), False),
]


@pytest.mark.parametrize(("held", "asked", "taken"), RACE_CASES, ids=[f"{h}->{a}" for h, a, _ in RACE_CASES])
def test_the_multi_agent_table_takes_from_the_csv_only_the_same_settings(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, held: tuple, asked: tuple, taken: bool) -> None:
    ran: list[ma.RaceTask] = []

    def fake_race(task: ma.RaceTask, policy=None, *_, **__) -> ma.RaceResult:
        ran.append(task)
        return ma.RaceResult(task.track, task.strategy.name, task.strategy.policy_id, task.seed, task.cars,
                             task.duration, task.stack, task.scenario, 0, 0, 0, 0, task.cars, 1.0,
                             float(task.strategy.gamma), "", 0.0, task.opponents, task.config_hash)

    monkeypatch.setattr(ma, "run_race", fake_race)

    def run(gamma: float, duration: float) -> ma.MultiAgentReport:
        return ma.run_multi_agent_table([ev.Strategy.fixed(gamma)], tmp_path, tracks=["Monza"], races=1,
                                        duration=duration, progress=False)

    run(*held)
    ran.clear()
    report = run(*asked)
    assert (report.skipped, len(ran)) == ((1, 0) if taken else (0, 1))
    assert ev.Strategy.fixed(asked[0]).label in report.markdown
    assert [r.strategy for r in report.rows] == [ev.Strategy.fixed(asked[0]).name]
    assert [r.duration for r in report.rows] == [asked[1]]


def test_committed_rows_keep_their_keys() -> None:
    """The committed Table I rows of the fixed gammas read under the keys of today's tasks."""
    path = Path(__file__).resolve().parents[2] / "results" / "interactive_dense" / "table1_episodes.csv"
    rows = ev.read_episode_csv(path)
    names = {r["strategy"] for r in rows}
    assert {ev.Strategy.fixed(g).name for g in ev.FIXED_GAMMAS} <= names


# (gamma of the run, is it put next to the paper's Table I?)
PAPER_CASES = [(0.05, True), (0.3, True), (0.054, False), (0.075, False), (0.31, False)]


@pytest.mark.parametrize(("gamma", "compared"), PAPER_CASES, ids=[str(g) for g, _ in PAPER_CASES])
def test_only_the_paper_gammas_are_compared_with_the_paper(gamma: float, compared: bool) -> None:
    s = ev.Strategy.fixed(gamma)
    rows = [{**_result(t).to_row(), "success": True}
            for t in ev.table1_tasks([s], ["Monza"], [0.3], 2, duration=1.0)]
    assert bool(ev.paper_comparison(rows, [s])) == compared


# (two interventions, do they share a label?)
LABEL_CASES = [
    (Intervention(0.05, 2.0), Intervention(0.054, 2.0), False),
    (Intervention(0.3, 1.0), Intervention(0.3, 1.0000001), False),
    (Intervention(0.3, 2.0, lead_s=20.0), Intervention(0.3, 2.0, lead_s=20.00001), False),
    (Intervention(0.3, 2.0), Intervention(0.30, 2.0), True),
]


@pytest.mark.parametrize(("a", "b", "same"), LABEL_CASES, ids=[f"{a.label}|{b.label}" for a, b, _ in LABEL_CASES])
def test_interventions_share_a_label_only_when_they_are_the_same(a: Intervention, b: Intervention,
                                                                 same: bool) -> None:
    assert (a.label == b.label) == same
