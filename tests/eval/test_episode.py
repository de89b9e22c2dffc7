"""sofar_agents.evaluation.episode: the environment of an episode, the episode loop and its record."""

from __future__ import annotations

import numpy as np
import pytest

from sofar_agents import evaluation as ev


def test_slack_active_from_info():
    assert ev.slack_active({"barrier_slack": 1e-3})
    assert not ev.slack_active({"barrier_slack": 1e-6, "cost": 5.0})  # barrier_slack wins over the cost
    assert not ev.slack_active({"cost": 1.0, "collision": True})  # the cost of a collision is no slack
    assert ev.slack_active({"cost": 1.5, "collision": True})
    assert ev.slack_active({"cost": np.array([0.01])})
    assert not ev.slack_active({})


def test_paired_episodes_start_identically():
    """Same seed -> same initial ego state and opponent field whatever the strategy."""
    tasks = ev.table1_tasks([ev.Strategy.fixed(0.05), ev.Strategy.fixed(0.95)], ["LagunaSeca"], [0.5], 2,
                            duration=1.0)
    env = ev.make_env("LagunaSeca", True, 1.0)
    try:
        first = {}
        for t in tasks:
            obs, _ = env.reset(seed=t.seed, options={"rho": t.rho})
            first.setdefault(t.episode, []).append(np.asarray(obs).copy())
        for e, obs_list in first.items():
            np.testing.assert_array_equal(obs_list[0], obs_list[1])
        assert not np.array_equal(first[0][0], first[1][0])
        # and the episode itself is deterministic
        res = [ev.run_episode(env, ev.Strategy.fixed(0.5).build(), tasks[0])[0] for _ in range(2)]
        a, b = (r.to_row() for r in res)
        a.pop("wall_time"), b.pop("wall_time")
        assert a == b and a["steps"] == 10
    finally:
        env.close()


def test_episode_record_and_trace():
    """Horizon, options and trace rows of a short episode with two opponents."""
    env = ev.make_env("LagunaSeca", True, 0.5, stack="paper")
    try:
        task = ev.EpisodeTask("LagunaSeca", ev.Strategy.fixed(0.3), 0.5, 2, 17, True, 0.5, n_opponents=2,
                              stack="paper", trace=True)
        result, trace = ev.run_episode(env, ev.Strategy.fixed(0.3).build(), task)
    finally:
        env.close()
    row = result.to_row()
    assert list(row) == list(ev.EPISODE_COLUMNS)
    assert (row["steps"], row["episode"], row["seed"], row["stack"], row["n_opponents"]) == (5, 2, 17, "paper", 2)
    assert row["success"] and row["sim_time"] >= 0.5 - 1e-6 and row["mean_gamma"] == pytest.approx(0.3, abs=1e-6)
    assert len(trace) == 5 and all(len(r) == len(ev.TRACE_COLUMNS) for r in trace)
    assert [r[4] for r in trace] == [1, 2, 3, 4, 5]
    assert {r[:4] for r in trace} == {("LagunaSeca", "gamma=0.30", "0.5", 17)}
