"""Self-play: the PettingZoo race as a vector of per-car slots for PASTA, and ``train/pasta.py --multi-agent``."""

from __future__ import annotations

import functools
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from sofar_agents import PASTA, PASTAConfig, load_policy
from sofar_agents.pasta.self_play import RaceVectorEnv, make_self_play_race

ROOT = Path(__file__).resolve().parents[2]
SHORT = {"race": {"duration": 3.0}, "speed_factors": (0.7, 0.85, 0.8)}


def make_vec(n_races: int = 1, n_cars: int = 3, **kwargs) -> RaceVectorEnv:
    return RaceVectorEnv([functools.partial(make_self_play_race, "LagunaSeca", n_cars, {**SHORT, **kwargs})
                          for _ in range(n_races)])


def test_slots_are_the_cars_of_the_races_and_seeding_is_per_race():
    venv = make_vec(n_races=2)
    assert venv.num_envs == 6 and venv.single_observation_space.shape == (12,)
    assert venv.get_attr("objective_names")[0][1] == "overtakes" and venv.reward_space.shape == (5,)
    obs, _ = venv.reset(seed=4)
    assert obs.shape == (6, 12)
    first, _ = make_self_play_race("LagunaSeca", 3, SHORT).reset(seed=5)
    np.testing.assert_array_equal(obs[3:], np.stack([first[f"car_{i}"] for i in range(3)]))  # race 1: seed + 1
    again, _ = make_vec(n_races=2).reset(seed=4)
    np.testing.assert_array_equal(obs, again)


def test_race_duration_truncates_every_car_and_resets_the_race():
    venv = make_vec()
    venv.reset(seed=0)
    actions = np.full((3, 1), 0.5, np.float32)
    for _ in range(29):
        obs, rewards, term, trunc, infos = venv.step(actions)
        assert rewards.shape == (3, 5) and not (term.any() or trunc.any()) and infos == {}
    obs, rewards, term, trunc, infos = venv.step(actions)  # 3 s: the race ends
    assert trunc.all() and not term.any()
    assert all(infos["final_info"]["is_success"]) and infos["_final_obs"].all()
    assert venv.races[0].race.time == 0.0  # reset in the same step
    assert not np.array_equal(obs[0], infos["final_obs"][0])


def test_a_collision_ends_the_race_for_every_car():
    venv = make_vec()
    venv.reset(seed=0)
    race = venv.races[0].race
    x, y = race.track.to_cartesian(float(race.frenet[1, 0]) + 1.0, float(race.frenet[1, 1]))
    race.states[2, :2] = (x, y)  # car 2 onto car 1
    race.states[2, 2] = race.states[1, 2]
    obs, rewards, term, trunc, infos = venv.step(np.full((3, 1), 0.5, np.float32))
    assert term.tolist() == [False, True, True] and trunc.tolist() == [True, False, False]
    final = infos["final_info"]
    assert final["collision"][1] and final["collision"][2] and not final["collision"][0]
    assert final["is_success"][1] is False and final["is_success"][2] is False
    assert final["is_success"][0] is None  # car 0 did not finish its race: neither success nor failure
    assert rewards[1, 0] < 0 and rewards[2, 0] < 0  # the safety objective pays for the collision
    assert venv.races[0].agents == ["car_0", "car_1", "car_2"] and race.time == 0.0  # a new race


def test_pasta_collects_and_updates_on_the_race():
    venv = make_vec(n_cars=2)
    agent = PASTA(12, 5, [0.05], [1.0], PASTAConfig(n_steps=16, n_epochs=1, batch_size=16, hidden_sizes=(16, 16),
                                                   critic_head_hidden=8), seed=1)
    buffer = agent.collect(venv, 32)  # 3 s races: every slot finishes one episode
    assert buffer.obs.shape == (32, 2, 12) and agent.num_timesteps == 64
    assert len(buffer.episodes) == 2 and all(e["length"] == 30 for e in buffer.episodes)
    assert buffer.truncated[29].all()
    stats = agent.update(buffer)
    assert np.isfinite(stats["policy_loss"])


def test_a_race_in_scalar_reward_mode_is_refused():
    from sofar_env.multi_agent import parallel_env

    with pytest.raises(ValueError, match="reward_mode='vector'"):
        RaceVectorEnv([lambda: parallel_env("LagunaSeca", n_agents=2)])


def test_train_script_multi_agent_smoke(tmp_path: Path):
    out = tmp_path / "selfplay"
    cmd = [sys.executable, "train/pasta.py", "--multi-agent", "--cars", "3", "--total-steps", "192", "--n-steps",
           "32", "--n-epochs", "1", "--batch-size", "32", "--hidden-sizes", "32", "32", "--seed", "2",
           "--env-kwargs", '{"race": {"duration": 2.0}}', "--out", str(out), "--no-progress", "--save-every", "1"]
    proc = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=600,
                          env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert proc.returncode == 0, proc.stderr
    # 20-step races in rollouts of 32 steps: 3 cars finish one race in the first, two in the second
    assert "update 1  steps 96/192  episodes +3" in proc.stderr and "update 2  steps 192/192  episodes +6" in proc.stderr
    assert list((out / "tb").glob("events.out.tfevents.*"))
    final = out / "pasta_final.json"
    meta = json.loads(final.read_text())["training"]
    assert meta["multi_agent"] is True and meta["cars"] == 3 and meta["rho"] is None and meta["seed"] == 2
    assert "--multi-agent" in meta["command"] and meta["num_timesteps"] == 192 and meta["wall_time_s"] > 0
    assert PASTA.load(final).num_timesteps == 192

    from sofar_env.multi_agent import parallel_env

    policy = load_policy(final, obs_dim=12)
    env = parallel_env("LagunaSeca", n_agents=3, race={"duration": 1.0})
    obs, _ = env.reset(seed=0)
    while env.agents:
        obs, _, _, _, infos = env.step({a: policy(obs[a]) for a in env.agents})
    assert all(0.05 <= info["gamma"] <= 1.0 for info in infos.values())
