"""The Gymnasium environment: registration, conformance, spaces, rewards, episode end, determinism."""

import functools
import math
import pickle
import subprocess
import sys

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import sofar_env
from sofar_env.config import OBJECTIVE_NAMES
from sofar_env.env import SOfARRaceEnv
from sofar_env.registration import ENV_IDS

SHORT = {"race": {"duration": 3.0}}  # 30 control steps
CHECK = {"race": {"duration": 3.0}}


def test_every_id_is_registered_with_a_string_entry_point_and_no_step_limit():
    assert ENV_IDS == ("SOfAR-LagunaSeca-v0", "SOfAR-Monza-v0", "SOfAR-Indianapolis-v0", "SOfAR-Kentucky-v0")
    for env_id in ENV_IDS:
        spec = gym.spec(env_id)
        assert spec.max_episode_steps is None  # the env truncates itself at its configured duration
        assert spec.entry_point == "sofar_env.factory:make_env"
        assert pickle.loads(pickle.dumps(spec)) == spec


def test_default_env_duration_is_2000_steps():
    env = gym.make("SOfAR-LagunaSeca-v0")
    assert env.unwrapped.config.race.max_steps == 2000 and env.spec.max_episode_steps is None
    env.close()


def test_package_import_is_light_and_make_works_without_import():
    code = (
        "import sys, gymnasium\n"
        "env = gymnasium.make('sofar_env:SOfAR-Monza-v0')\n"
        "assert env.unwrapped.config.track == 'Monza'\n"
        "import sofar_env, importlib\n"
        "assert callable(sofar_env.parallel_env)\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True)
    light = (
        "import sys, sofar_env\n"
        "heavy = [m for m in ('casadi', 'torch', 'matplotlib', 'PIL', 'pettingzoo') if m in sys.modules]\n"
        "assert not heavy, heavy\n"
    )
    subprocess.run([sys.executable, "-c", light], check=True)


def test_construction_is_cheap_controllers_are_built_on_reset():
    env = SOfARRaceEnv(**SHORT)
    assert env.race is None and env.stack is None
    env.reset(seed=0)
    assert env.stack is not None
    env.close()


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_gymnasium_check_env_on_every_id(env_id):
    env = gym.make(env_id, config=CHECK)
    check_env(env.unwrapped, skip_render_check=True)
    env.close()


def test_gymnasium_check_env_on_the_default_env():
    """A user's first check: the registered id exactly as gym.make gives it."""
    env = gym.make("SOfAR-LagunaSeca-v0")
    check_env(env.unwrapped)
    env.close()


def test_gymnasium_check_env_with_rendering():
    env = gym.make("SOfAR-LagunaSeca-v0", config=CHECK, render_mode="rgb_array")
    check_env(env.unwrapped)
    env.close()


def test_sb3_check_env():
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    env = SOfARRaceEnv(**SHORT)
    with pytest.warns(UserWarning, match="symmetric"):  # gamma in [0.05, 1] is deliberately not [-1, 1]
        sb3_check_env(env, warn=True)
    env.close()


def test_spaces():
    env = SOfARRaceEnv(**SHORT)
    assert env.action_space == gym.spaces.Box(0.05, 1.0, (1,), np.float32)
    assert env.observation_space == gym.spaces.Box(-1.0, 1.0, (12,), np.float32)
    assert env.objective_names == OBJECTIVE_NAMES == (
        "safety", "overtakes", "progress", "barrier_margin", "gamma_smoothness")
    assert not hasattr(env, "reward_space")  # scalar mode: not a multi-objective env
    space = SOfARRaceEnv(reward_mode="vector", **SHORT).reward_space
    assert space.shape == (5,) and space.dtype == np.float32
    assert env.metadata["render_fps"] == 10 and set(env.metadata["render_modes"]) == {"human", "rgb_array"}


def test_first_observation_reads_absent_opponents_as_far():
    env = SOfARRaceEnv(n_opponents=0, **SHORT)
    obs, info = env.reset(seed=3, options={"start_speed": 40.0})
    assert obs.dtype == np.float32 and obs.shape == (12,)
    assert obs[3] == obs[4] == 1.0  # gap at the upper clip (200 m)
    assert np.all(obs[5:9] == 0.0)
    assert obs[1] == pytest.approx(40.0 / 50.0 - 1.0)
    assert info["nearest_opponent_m"] == math.inf and info["min_barrier"] == math.inf
    env.close()


def test_observation_sees_the_nearest_opponents_in_gap_order():
    env = SOfARRaceEnv(offsets=(0.0, 1.0, -1.0, 0.0), race={"duration": 3.0, "opponents": {"gaps": (60, 30, 250, 400)}})
    obs, _ = env.reset(seed=0)
    gaps = (obs[3:5] + 1.0) * 110.0 - 20.0
    np.testing.assert_allclose(gaps, [30.0, 60.0], atol=1e-3)
    np.testing.assert_allclose(obs[5:7] * 15.0, [1.0, 0.0], atol=1e-6)
    env.close()


def test_a_reset_reproduces_the_episode_and_only_the_solve_times_differ():
    env = SOfARRaceEnv(rho=0.5, **SHORT)
    runs = []
    for _ in range(2):
        obs, info = env.reset(seed=5)
        steps = [(obs, 0.0, info)]
        for g in (0.3, 0.8, 0.5, 0.5, 0.1):
            obs, r, _, _, info = env.step(np.array([g], np.float32))
            steps.append((obs, r, info))
        runs.append(steps)
    for (o1, r1, i1), (o2, r2, i2) in zip(*runs):
        np.testing.assert_array_equal(o1, o2)
        assert r1 == r2
        assert set(i1) == set(i2)
        differ = {k for k in i1 if not np.array_equal(np.asarray(i1[k]), np.asarray(i2[k]))}
        assert not differ
    env.close()


def test_same_seed_same_trajectory():
    actions = np.random.default_rng(1).uniform(0.05, 1.0, size=(50, 1)).astype(np.float32)

    def rollout(seed):
        env = SOfARRaceEnv(rho=0.5, race={"duration": 10.0})
        obs, _ = env.reset(seed=seed)
        out = [obs]
        rewards = []
        for a in actions:
            obs, r, term, trunc, info = env.step(a)
            out.append(obs)
            rewards.append(info["reward_vector"])
            if term or trunc:
                break
        env.close()
        return np.array(out), np.array(rewards)

    a, b, c = rollout(11), rollout(11), rollout(12)
    np.testing.assert_array_equal(a[0], b[0])
    np.testing.assert_array_equal(a[1], b[1])
    assert not np.array_equal(a[0][0], c[0][0])


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_actions_raise(bad):
    env = SOfARRaceEnv(**SHORT)
    env.reset(seed=0)
    with pytest.raises(ValueError, match="non-finite"):
        env.step(np.array([bad], np.float32))
    env.close()


def test_out_of_range_actions_are_clipped():
    env = SOfARRaceEnv(**SHORT)
    env.reset(seed=0)
    assert env.step(np.array([5.0], np.float32))[4]["gamma"] == 1.0
    assert env.step(np.array([-3.0], np.float32))[4]["gamma"] == pytest.approx(0.05)
    assert env.step(np.array([0.3], np.float32))[4]["gamma"] == pytest.approx(0.3)
    with pytest.raises(ValueError):
        env.step(np.array([0.3, 0.4], np.float32))
    env.close()


def test_step_before_reset_raises():
    with pytest.raises(gym.error.ResetNeeded):
        SOfARRaceEnv(**SHORT).step(np.array([0.5], np.float32))


def test_unknown_reset_option_raises():
    env = SOfARRaceEnv(**SHORT)
    with pytest.raises(ValueError, match="unknown reset option"):
        env.reset(seed=0, options={"speed": 3})


def test_reset_options_apply_to_the_episode():
    env = SOfARRaceEnv(**SHORT)
    env.reset(seed=0, options={"rho": 0.65, "n_opponents": 2, "start_s": 500.0, "start_speed": 30.0})
    assert env.race.opponents.count == 2 and env.race.opponents.rho == 0.65
    assert env.race.frenet[0, 0] == pytest.approx(500.0) and env.race.frenet[0, 3] == 30.0
    env.reset(seed=0)
    assert env.race.opponents.count == 4 and env.race.opponents.rho == 0.3
    env.close()


def test_scalar_reward_is_the_weighted_vector_and_vector_mode_returns_the_vector():
    weights = np.array([10.0, 1.0, 0.05, 0.5, 0.1])
    env = SOfARRaceEnv(rho=0.5, **SHORT)
    venv = SOfARRaceEnv(rho=0.5, reward_mode="vector", **SHORT)
    env.reset(seed=4)
    venv.reset(seed=4)
    previous = 0.5  # initial_gamma
    for g in [0.5, 0.9, 0.2, 0.2, 0.7] * 4:
        _, r, term, trunc, info = env.step(np.array([g], np.float32))
        _, rv, *_ = venv.step(np.array([g], np.float32))
        assert isinstance(r, float)
        assert r == pytest.approx(float(weights @ info["reward_vector"].astype(float)), rel=1e-5, abs=1e-6)
        assert rv.dtype == np.float32 and rv.shape == (5,)
        np.testing.assert_array_equal(rv, info["reward_vector"])
        assert info["reward_vector"][4] == pytest.approx(-abs(g - previous), abs=1e-6)
        assert venv.reward_space.contains(rv)
        previous = g
        if term or trunc:
            break
    env.close()
    venv.close()


def test_info_keys():
    env = SOfARRaceEnv(**SHORT)
    _, info0 = env.reset(seed=0)
    _, _, _, _, info = env.step(np.array([0.5], np.float32))
    expected = {"reward_vector", "overtakes", "laps", "sim_time", "gamma", "collision", "off_track",
                "nearest_opponent_m", "min_barrier", "cost", "mpc_status", "miqp_sides",
                "mpc_failures", "miqp_failures", "barrier_slack"}
    assert expected <= set(info) and expected <= set(info0)
    assert not {"mpc_time_ms", "miqp_time_ms"} & set(info)  # wall-clock times are opt-in
    assert info["sim_time"] == pytest.approx(0.1)
    assert info["mpc_status"] == "solved"
    env.close()


def test_timing_info_opt_in():
    env = SOfARRaceEnv(timing_info=True, **SHORT)
    env.reset(seed=0)
    _, _, _, _, info = env.step(np.array([0.5], np.float32))
    assert info["mpc_time_ms"] > 0 and info["miqp_time_ms"] >= 0
    assert 0 < info["laps"] < 0.01
    assert "is_success" not in info
    env.close()


def test_termination_on_collision():
    env = SOfARRaceEnv(rho=0.2, **SHORT)
    env.reset(seed=0, options={"start_speed": 30.0})
    race = env.race
    # teleport opponent 0 onto the ego
    race.opponents.s[0] = race.track.wrap(race.frenet[0, 0] + 2.0)
    race.opponents.n[0] = race.frenet[0, 1]
    obs, reward, terminated, truncated, info = env.step(np.array([0.5], np.float32))
    assert terminated and not truncated
    assert info["collision"] and info["is_success"] is False
    assert info["reward_vector"][0] == -1.0 and info["cost"] >= 1.0
    assert reward <= -10.0 + 1.0
    assert info["nearest_opponent_m"] < 5.0 and info["min_barrier"] < 0.0
    assert env.observation_space.contains(obs)
    env.close()


def test_termination_when_leaving_the_track():
    env = SOfARRaceEnv(n_opponents=0, **SHORT)
    env.reset(seed=0)
    race = env.race
    s = float(race.frenet[0, 0])
    x, y = race.track.to_cartesian(s, float(race.track.width_left(s)) + 0.5)
    race.states[0, :2] = (x, y)
    _, _, terminated, _, info = env.step(np.array([0.5], np.float32))
    assert terminated and info["off_track"] and not info["collision"]
    assert info["reward_vector"][0] == -1.0
    env.close()


@pytest.mark.parametrize("k, expected_steps", [(1, 10), (3, 4)])
def test_truncation_at_the_race_duration_whatever_the_decision_interval(k, expected_steps):
    env = SOfARRaceEnv(decision_interval=k, n_opponents=0, race={"duration": 1.0})
    env.reset(seed=0)
    for i in range(1, 20):
        _, _, terminated, truncated, info = env.step(np.array([0.5], np.float32))
        if truncated:
            break
        assert not terminated and "is_success" not in info
    assert i == expected_steps
    assert info["sim_time"] == pytest.approx(1.0)
    assert info["is_success"] is True and not terminated
    env.close()


def test_decision_interval_sums_the_control_steps():
    env = SOfARRaceEnv(decision_interval=2, n_opponents=0, **SHORT)
    env.reset(seed=0)
    _, _, _, _, info = env.step(np.array([0.5], np.float32))
    assert info["sim_time"] == pytest.approx(0.2)
    assert 1.0 < info["reward_vector"][2] < 2.6  # progress of two control steps


def test_an_explicit_max_episode_steps_still_truncates():
    """gymnasium.make(..., max_episode_steps=N) adds Gymnasium's TimeLimit (the env's own duration is lengthened so
    that the limit acts first)."""
    env = gym.make("SOfAR-Kentucky-v0", n_opponents=0, race={"duration": 1000.0}, use_miqp=False,
                   max_episode_steps=2000)
    env.reset(seed=0)
    env.unwrapped.step = lambda action: (np.zeros(12, np.float32), 0.0, False, False, {})  # skip the physics
    for i in range(1, 2001):
        _, _, terminated, truncated, _ = env.step(np.array([0.5], np.float32))
        if truncated:
            break
    assert i == 2000 and truncated
    env.close()


def test_async_vector_env_with_two_workers():
    fn = functools.partial(gym.make, "SOfAR-LagunaSeca-v0", config=SHORT)
    envs = gym.vector.AsyncVectorEnv([fn, fn])
    try:
        obs, info = envs.reset(seed=[0, 1])
        assert obs.shape == (2, 12)
        for _ in range(3):
            obs, rew, term, trunc, info = envs.step(np.full((2, 1), 0.5, np.float32))
        assert obs.shape == (2, 12) and rew.shape == (2,)
        assert np.all(info["sim_time"] > 0.0)
    finally:
        envs.close()
