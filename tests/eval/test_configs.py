"""Configuration hashes of result rows: the column, resume keys, config.json, and readers that refuse to mix."""

from __future__ import annotations

import csv
import dataclasses
import json

import pytest

from sofar_agents import evaluation as ev
from sofar_agents.evaluation import configs
from sofar_agents.evaluation.results import _AppendingCSV, _row_key, rows_of_other_configs
from sofar_env.config_hash import config_hash


def _task(**kw) -> ev.EpisodeTask:
    args = dict(track="Monza", strategy=ev.Strategy.fixed(0.5), rho=0.3, episode=0, seed=42, duration=200.0)
    args.update(kw)
    return ev.EpisodeTask(**args)


def _row(task: ev.EpisodeTask, **kw) -> dict:
    fields = dict(track=task.track, strategy=task.strategy.name, rho=task.rho, seed=task.seed, success=True,
                  sim_time=1.0, laps=0.1, overtakes=0, collision=False, off_track=False, slack_steps=0, steps=10,
                  mean_gamma=0.5, mpc_failures=0, miqp_failures=0, wall_time=0.1, episode=task.episode,
                  use_miqp=task.use_miqp, duration=task.duration, stack=task.stack, scenario=task.scenario,
                  config_hash=task.config_hash)
    fields.update(kw)
    return ev.EpisodeResult(**fields).to_row()


def test_the_column_sits_next_to_stack_and_tasks_carry_the_resolved_hash() -> None:
    cols = ev.EPISODE_COLUMNS
    assert cols[cols.index("stack") + 1] == "config_hash"
    t = _task()
    assert t.config_hash == config_hash(configs.episode_config("sofar", "paper", 200.0))
    assert _task(track="Kentucky", rho=0.7, use_miqp=False).config_hash == t.config_hash  # one table, one hash
    assert _task(stack="paper").config_hash != t.config_hash
    assert _task(duration=100.0).config_hash != t.config_hash
    assert t.key != _task(pinned_hash="").key != _task(pinned_hash="abc").key


def test_a_row_resumes_only_the_task_of_its_hash(tmp_path) -> None:
    path = tmp_path / "table1_episodes.csv"
    t = _task()
    out = _AppendingCSV(path, ev.EPISODE_COLUMNS)
    out.write(_row(t))
    out.write(_row(dataclasses.replace(t, pinned_hash=""), seed=43))  # hypothetical: the same settings, no hash
    out.close()
    rows = ev.read_episode_csv(path)
    assert _row_key(rows[0]) == t.key and rows[0]["config_hash"] == t.config_hash
    other = dataclasses.replace(t, seed=43)
    assert [r["seed"] for r in ev.select_rows(rows, [t, other])] == [42]  # the unhashed row is another config
    assert rows_of_other_configs(rows, [t, other]) == {"": 1}


def test_select_rows_and_tables_refuse_two_hashes_under_one_label(tmp_path) -> None:
    a, b = _task(), _task(seed=43, pinned_hash="0123456789ab")
    rows = [_row(a), _row(b)]
    with pytest.raises(ValueError, match=rf"{a.config_hash}.*0123456789ab"):
        ev.select_rows(rows, [a, b])
    with pytest.raises(ValueError, match="two configurations"):
        ev.format_table1(rows)
    unhashed = [_row(a), _row(_task(seed=43, pinned_hash=""))]
    with pytest.raises(ValueError, match="no hash"):
        ev.format_table1(unhashed)


def test_paired_comparison_refuses_rows_of_two_configurations() -> None:
    a05, a03 = ev.Strategy.fixed(0.5), ev.Strategy.fixed(0.3)
    first = [_row(_task(strategy=s)) for s in (a05, a03)]
    second = [_row(_task(strategy=s, seed=7, pinned_hash=""), seed=7) for s in (a05, a03)]
    assert ev.paired_comparison({"one": first}, "gamma=0.50", "gamma=0.30").n == 1
    with pytest.raises(ValueError, match="paired comparison.*no hash"):
        ev.paired_comparison({"one": first, "two": second}, "gamma=0.50", "gamma=0.30")


def test_config_json_is_written_once_per_hash_and_reads_back(tmp_path) -> None:
    sofar = configs.episode_config("sofar", "paper", 200.0)
    paper = configs.episode_config("paper", "paper", 200.0)
    path = configs.write_config_json(tmp_path, [sofar])
    first = path.read_bytes()
    configs.write_config_json(tmp_path, [sofar])
    assert path.read_bytes() == first  # nothing new: not rewritten
    configs.write_config_json(tmp_path, [paper])
    got = configs.read_config_json(tmp_path)
    assert set(got) == {config_hash(sofar), config_hash(paper)}
    data = json.loads(path.read_text())
    data["configs"][config_hash(sofar)]["race"]["duration"] = 1.0
    path.write_text(json.dumps(data))
    with pytest.raises(ValueError, match="has hash"):
        configs.read_config_json(tmp_path)
    assert not list(tmp_path.glob(".*.tmp"))


def test_the_episode_row_carries_the_environment_hash_and_a_wrong_task_hash_raises() -> None:
    task = _task(track="LagunaSeca", duration=0.3)
    env = ev.make_env(task.track, task.use_miqp, task.duration, task.stack, task.scenario)
    try:
        result, _ = ev.run_episode(env, ev.Strategy.fixed(0.5).build(), task)
        assert result.config_hash == task.config_hash == configs.episode_config_hash("sofar", "paper", 0.3)
        with pytest.raises(RuntimeError, match="config_hash"):
            ev.run_episode(env, ev.Strategy.fixed(0.5).build(), dataclasses.replace(task, pinned_hash="0" * 12))
    finally:
        env.close()


def test_old_csv_is_migrated_with_an_empty_hash(tmp_path) -> None:
    path = tmp_path / "table1_episodes.csv"
    old_cols = [c for c in ev.EPISODE_COLUMNS if c != "config_hash"]
    t = _task()
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=old_cols, extrasaction="ignore")
        w.writeheader()
        w.writerow({k: int(v) if isinstance(v, bool) else v for k, v in _row(t).items()})
    out = _AppendingCSV(path, ev.EPISODE_COLUMNS)
    out.write(_row(t))
    out.close()
    assert [r["config_hash"] for r in ev.read_episode_csv(path)] == ["", t.config_hash]
