"""sofar_agents.evaluation.sweep: a sweep appends each episode once, resumes, and leaves failures out."""

from __future__ import annotations

import dataclasses
import logging

import pytest

from sofar_agents import evaluation as ev


def test_sweep_runs_resumes_and_skips_failures(tmp_path, caplog):
    csv_path, trace_path = tmp_path / "episodes.csv", tmp_path / "trace.csv"
    tasks = ev.table1_tasks([ev.Strategy.fixed(0.5)], ["LagunaSeca"], [0.5], episodes=2, duration=0.3, trace=True)
    other_stack = dataclasses.replace(tasks[0], stack="paper")
    broken = dataclasses.replace(tasks[0], track="NoSuchTrack")
    with caplog.at_level(logging.ERROR, logger="sofar_agents.evaluation"):
        stats = ev.run_sweep(tasks + [tasks[0], other_stack, broken], csv_path, workers=1, trace_path=trace_path,
                             progress=False)
    assert (stats.requested, stats.skipped, stats.completed, stats.failed, stats.workers) == (5, 1, 3, 1, 1)
    assert stats.steps == 3 * 3 and len(stats.errors) == 1 and "NoSuchTrack" in caplog.text
    rows = ev.read_episode_csv(csv_path)
    assert sorted((r["seed"], r["stack"]) for r in rows) == sorted(
        [(tasks[0].seed, "sofar"), (tasks[1].seed, "sofar"), (tasks[0].seed, "paper")])
    assert ev.read_trace_csv(trace_path)["gamma"].size == 3 * 3
    # a rerun only retries the failed episode
    again = ev.run_sweep(tasks + [other_stack, broken], csv_path, workers=1, progress=False)
    assert (again.skipped, again.completed, again.failed) == (3, 0, 1)
    assert len(ev.read_episode_csv(csv_path)) == 3


def test_sweep_stats_speed_and_estimate():
    st = ev.SweepStats(completed=2, steps=1000, episode_wall_time=10.0, workers=2)
    assert st.steps_per_second_per_worker == 100.0
    assert st.estimate_hours(3.6e6, 10) == 1.0
    assert ev.SweepStats().steps_per_second_per_worker != ev.SweepStats().steps_per_second_per_worker  # NaN


@pytest.mark.parametrize("run", ["sweep", "multi-agent table"])
@pytest.mark.parametrize("workers", [0, -2])
def test_zero_or_negative_workers_are_refused_not_all_cpus(tmp_path, run, workers):
    """0 is not "unset" (None is): a sweep asked for 0 workers raises before it reads or runs anything."""
    from sofar_agents.evaluation.multi_agent import run_multi_agent_table

    with pytest.raises(ValueError, match="workers must be >= 1"):
        if run == "sweep":
            ev.run_sweep(ev.table1_tasks([ev.Strategy.fixed(0.5)], ["LagunaSeca"], [0.5], episodes=1, duration=0.3),
                         tmp_path / "e.csv", workers=workers, progress=False)
        else:
            run_multi_agent_table([ev.Strategy.fixed(0.5)], tmp_path / "ma", tracks=["LagunaSeca"], races=1,
                                  workers=workers, progress=False)
    assert not any(tmp_path.iterdir())
