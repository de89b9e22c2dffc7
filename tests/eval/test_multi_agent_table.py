"""The multi-agent table: paired seeded races per strategy, resumable CSV, the Markdown report."""

from __future__ import annotations

from pathlib import Path

from sofar_agents.evaluation.manifest_spec import load_manifest
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
    with __import__("pytest").raises(SystemExit) as exc:  # a usage error of the argument type
        table.main(["--multi-agent", "--cars", "1"])
    assert exc.value.code == 2 and "argument --cars: must be a whole number >= 2" in capsys.readouterr().err


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
    assert len(rows) == 256 and len({r.key for r in rows}) == 256  # 4 strategies x 4 circuits x 16 races
    manifest = load_manifest(root.parents[1] / "experiments" / "multi_agent.toml")
    self_play = Strategy.adaptive(root.parents[1] / manifest.self_play, name="self-play")  # the policy it names
    assert {r.policy_id for r in rows if r.strategy == "self-play"} == {self_play.policy_id}


def test_a_mixed_field_enters_the_key_and_the_report(tmp_path: Path):
    """--opponents with --multi-agent: scripted cars beside the controlled ones, their own resume key."""
    kwargs = dict(tracks=["Monza"], races=1, base_seed=3, cars=2, duration=2.0, progress=False)
    plain = run_multi_agent_table(STRATEGIES[:1], tmp_path, **kwargs)
    mixed = run_multi_agent_table(STRATEGIES[:1], tmp_path, opponents=2, **kwargs)
    assert (mixed.completed, mixed.skipped) == (1, 0)  # not taken for the race without scripted cars
    assert [r.opponents for r in read_race_csv(plain.csv_path)] == [0, 2]
    assert "2 cars and 2 scripted opponents" in mixed.markdown and "lapping it is another pass" in mixed.markdown
    assert "scripted" not in plain.markdown.split("\n")[2]
    # a CSV written before the column reads as races without scripted opponents
    lines = plain.csv_path.read_text().splitlines()
    old = "\n".join([lines[0].rsplit(",", 1)[0], lines[1].rsplit(",", 1)[0]]) + "\n"
    (tmp_path / "old.csv").write_text(old)
    assert read_race_csv(tmp_path / "old.csv")[0].opponents == 0
    # resuming into it rewrites it in the current layout, keeping its race
    (tmp_path / "old").mkdir()
    (tmp_path / "old" / "multi_agent_races.csv").write_text(old)
    resumed = run_multi_agent_table(STRATEGIES, tmp_path / "old", **kwargs)
    assert (resumed.completed, resumed.skipped) == (1, 1)
    assert [r.key for r in read_race_csv(tmp_path / "old" / "multi_agent_races.csv")] == [r.key for r in resumed.rows]


def test_race_script_with_the_alongside_lock_on_the_table_seeds(capsys):
    import importlib.util

    spec = importlib.util.spec_from_file_location(
        "eval_ma_races", Path(__file__).resolve().parents[2] / "eval" / "multi_agent_races.py")
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    assert script.main(["--tracks", "Monza", "--table-races", "1", "--duration", "2", "--cars", "2",
                        "--alongside-gap", "6", "--races"]) == 0
    out = capsys.readouterr().out
    assert "alongside lock 6 m" in out and "first 1 races per circuit" in out
    from sofar_agents.evaluation.multi_agent import race_seed

    assert f"| Monza | {race_seed(0, 'Monza', 0)} |" in out
    with __import__("pytest").raises(SystemExit):
        script.main(["--alongside-gap", "-1"])


def test_run_race_applies_stack_overrides():
    from sofar_agents.evaluation.multi_agent import RaceTask, run_race

    task = RaceTask("Monza", Strategy.fixed(0.5), 3, cars=2, duration=1.0, stack="paper")
    r = run_race(task, stack_overrides={"miqp": {"alongside_gap": 6.0}})
    assert r.success == 2 and r.stack == "paper"
