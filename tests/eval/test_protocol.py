"""sofar_agents.evaluation.protocol: strategies, paired seeds, task lists and resume keys."""

from __future__ import annotations

import dataclasses

import pytest

from sofar_agents import evaluation as ev


def test_strategy_validation_and_labels():
    s = ev.Strategy.fixed(0.3)
    assert (s.name, s.kind, s.gamma, s.label, s.policy_id) == ("gamma=0.30", "fixed", 0.3, "γ = 0.30", "")
    with pytest.raises(ValueError):
        ev.Strategy("x", "fixed", gamma=0.0)
    with pytest.raises(ValueError):
        ev.Strategy("x", "fixed", gamma=1.5)
    with pytest.raises(ValueError):
        ev.Strategy("x", "policy")  # a policy needs a path
    with pytest.raises(ValueError):
        ev.Strategy("x", "nonsense", gamma=0.5)


def test_build_strategies_order_and_duplicates(tmp_path):
    assert [s.name for s in ev.build_strategies([0.05, 0.5], adaptive=False)] == ["gamma=0.05", "gamma=0.50"]
    with pytest.raises(ValueError, match="duplicate"):
        ev.build_strategies([0.5, 0.5], adaptive=False)
    with pytest.raises(FileNotFoundError):
        ev.build_strategies([0.5], sb3=tmp_path / "missing.zip", adaptive=False)
    with pytest.raises(FileNotFoundError):
        ev.resolve_policy_path(tmp_path / "missing")


def test_seeds_paired_across_strategies_and_deterministic():
    strategies = [ev.Strategy.fixed(g) for g in (0.05, 0.5, 0.95)]
    tasks = ev.table1_tasks(strategies, ["LagunaSeca", "Monza"], [0.1, 0.65], episodes=3, base_seed=7)
    assert len(tasks) == 2 * 2 * 3 * 3
    by_episode: dict[tuple, set] = {}
    for t in tasks:
        by_episode.setdefault((t.track, t.rho, t.episode), set()).add(t.seed)
    assert all(len(s) == 1 for s in by_episode.values())  # paired: one seed per episode, every strategy
    seeds = [next(iter(s)) for s in by_episode.values()]
    assert len(set(seeds)) == len(seeds)  # independent episodes
    again = ev.table1_tasks(strategies, ["LagunaSeca", "Monza"], [0.1, 0.65], episodes=3, base_seed=7)
    assert [t.seed for t in again] == [t.seed for t in tasks]
    # pinned value: a change in the derivation silently breaks resumed runs and paired comparisons
    assert ev.episode_seed(0, "LagunaSeca", 0.3, 0) == 954904027
    assert ev.episode_seed(1, "LagunaSeca", 0.3, 0) != ev.episode_seed(0, "LagunaSeca", 0.3, 0)
    # Table II episodes pair with Table I's and across the two MIQP settings
    abl = ev.miqp_ablation_tasks(strategies[:2], episodes=7, rhos=[0.1, 0.65], track="LagunaSeca", base_seed=7)
    assert {(t.rho, t.seed) for t in abl if t.use_miqp} == {(t.rho, t.seed) for t in abl if not t.use_miqp}
    t1 = {(t.rho, t.episode): t.seed for t in tasks if t.track == "LagunaSeca"}
    assert all(t1[(t.rho, t.episode)] == t.seed for t in abl if t.episode < 3)
    assert len([t for t in abl if t.use_miqp]) == 7 * 2


def test_task_key_holds_every_setting_that_changes_an_episode():
    task = ev.EpisodeTask("Monza", ev.Strategy.fixed(0.5), 0.3, 0, 11)
    changed = [dataclasses.replace(task, **kw) for kw in (
        {"track": "Kentucky"}, {"strategy": ev.Strategy.fixed(0.7)}, {"rho": 0.5}, {"seed": 12},
        {"use_miqp": False}, {"duration": 20.0}, {"stack": "paper"}, {"n_opponents": 2})]
    keys = [task.key] + [t.key for t in changed]
    assert len(set(keys)) == len(keys)
    # the trace flag and the episode index do not change the episode
    assert dataclasses.replace(task, trace=True, episode=3).key == task.key
    # the environment is shared by tasks of the same track, MIQP setting, horizon and controller
    assert dataclasses.replace(task, rho=0.8, n_opponents=2).env_key == task.env_key
    assert dataclasses.replace(task, stack="paper").env_key != task.env_key


def test_full_table1_size():
    # 4 circuits x 5 rho x 5 episodes x (adaptive + 6 fixed gammas) x 2000 steps
    assert ev.FULL_TABLE1_STEPS == 4 * 5 * 5 * 7 * 2000


def test_scenario_and_stack_enter_the_resume_key_and_the_env_key():
    base = ev.EpisodeTask("Monza", ev.Strategy.fixed(0.5), 0.3, 0, 42)
    world = ev.EpisodeTask("Monza", ev.Strategy.fixed(0.5), 0.3, 0, 42, scenario="interactive")
    paper = ev.EpisodeTask("Monza", ev.Strategy.fixed(0.5), 0.3, 0, 42, stack="paper")
    assert len({base.key, world.key, paper.key}) == 3
    assert len({base.env_key, world.env_key, paper.env_key}) == 3
    tasks = ev.table1_tasks([ev.Strategy.fixed(0.5)], ["Monza"], [0.3], 1, scenario="interactive")
    assert all(t.scenario == "interactive" for t in tasks)


def test_table1_tasks_carry_the_field_size_into_the_resume_key():
    default = ev.table1_tasks([ev.Strategy.fixed(0.5)], ["Monza"], [0.3], 1)
    dense = ev.table1_tasks([ev.Strategy.fixed(0.5)], ["Monza"], [0.3], 1, n_opponents=8)
    assert default[0].n_opponents is None and dense[0].n_opponents == 8
    assert default[0].seed == dense[0].seed and default[0].key != dense[0].key
