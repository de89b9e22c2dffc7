"""The multi-agent table: paired seeded races per strategy, resumable CSV, the Markdown report."""

from __future__ import annotations

from pathlib import Path

from sofar_agents.evaluation.multi_agent import read_race_csv, run_multi_agent_table
from sofar_agents.evaluation.protocol import Strategy

STRATEGIES = [Strategy.fixed(0.3), Strategy.fixed(0.5)]


def test_races_are_paired_resumed_and_reported(tmp_path: Path):
    report = run_multi_agent_table(STRATEGIES, tmp_path, tracks=["Monza"], races=1, base_seed=3, cars=3, duration=2.0,
                                   progress=False)
    assert report.completed == 2 and len(report.rows) == 2
    a, b = report.rows
    assert a.speed_factors == b.speed_factors and len(a.speed_factors.split()) == 3  # same field for both
    assert (a.success, a.collided, a.driven, a.mean_gamma) == (3, 0, 1.0, 0.3)  # a 2 s race from the grid
    assert "| γ = 0.30 | 1 | 0.00 | 0 | 0.00 | 0.00 | 0.00 | 100 | 100 | 0.30 |" in report.markdown
    assert "## Per circuit" in report.markdown and report.markdown_path.read_text() == report.markdown

    csv_path = report.csv_path
    csv_path.write_text(csv_path.read_text()[:-5])  # a run killed while writing the last row
    assert len(read_race_csv(csv_path)) == 1
    again = run_multi_agent_table(STRATEGIES, tmp_path, tracks=["Monza"], races=1, base_seed=3, cars=3, duration=2.0,
                                  progress=False)
    assert (again.completed, again.skipped) == (1, 1)  # only the torn race is run again
    assert [r.key for r in read_race_csv(csv_path)] == [a.key, b.key]


def test_table_script_multi_agent_refuses_single_car_options(capsys):
    import importlib.util

    spec = importlib.util.spec_from_file_location("eval_table_ma", Path(__file__).resolve().parents[2] / "eval" / "table.py")
    table = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(table)
    assert table.main(["--multi-agent", "--rhos", "0.5"]) == 2
    assert table.main(["--multi-agent", "--cars", "1"]) == 2
    assert "--cars must be at least 2" in capsys.readouterr().err


def test_races_are_seeded_per_circuit_and_shared_by_the_strategies():
    from sofar_agents.evaluation.multi_agent import multi_agent_tasks, race_seed

    tasks = multi_agent_tasks(STRATEGIES, ["Monza", "Kentucky"], races=2, base_seed=0)
    assert len(tasks) == 8
    seeds = {(t.track, t.strategy.name): [] for t in tasks}
    for t in tasks:
        seeds[(t.track, t.strategy.name)].append(t.seed)
    assert seeds[("Monza", "gamma=0.30")] == seeds[("Monza", "gamma=0.50")] == [race_seed(0, "Monza", 0),
                                                                                race_seed(0, "Monza", 1)]
    assert not set(seeds[("Monza", "gamma=0.30")]) & set(seeds[("Kentucky", "gamma=0.30")])
    assert race_seed(1, "Monza", 0) != race_seed(0, "Monza", 0)


def test_the_committed_multi_agent_run_reads_fully():
    root = Path(__file__).resolve().parents[2] / "results" / "multi_agent"
    rows = read_race_csv(root / "multi_agent_races.csv")
    assert len(rows) == 64 and len({r.key for r in rows}) == 64  # 4 strategies x 4 circuits x 4 races
    self_play = Strategy.adaptive(root / "selfplay_lagunaseca.json", name="self-play")
    assert {r.policy_id for r in rows if r.strategy == "self-play"} == {self_play.policy_id}
