"""Vector-reward mode through MO-Gymnasium: ``mo_gymnasium.make``, its wrappers and vector envs."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

mog = pytest.importorskip("mo_gymnasium")
from mo_gymnasium.wrappers import LinearReward, MORecordEpisodeStatistics  # noqa: E402
from mo_gymnasium.wrappers.vector import MOSyncVectorEnv  # noqa: E402
from mo_gymnasium.wrappers.vector import MORecordEpisodeStatistics as VecMORecordEpisodeStatistics  # noqa: E402

import sofar_env  # noqa: E402,F401  (registers the ids)

ENV_ID = "SOfAR-Monza-v0"
CFG = {"reward_mode": "vector", "race": {"duration": 3.0}}


def _make():
    return mog.make(ENV_ID, config=CFG)


def test_make_returns_declared_vector_reward_without_warnings():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        env = _make()
        env.reset(seed=0)
        _, reward, _, _, info = env.step(env.action_space.sample())
    space = env.unwrapped.reward_space
    assert isinstance(reward, np.ndarray) and reward.shape == space.shape == (5,)
    assert reward.dtype == np.float32
    assert space.contains(reward)
    np.testing.assert_array_equal(info["reward_vector"], reward)
    env.close()


def test_linear_reward_and_episode_statistics():
    weights = np.array([1.0, 0.5, 0.0, 2.0, 1.0], dtype=np.float32)
    # statistics inside the scalarisation, so they record the vector returns
    env = LinearReward(MORecordEpisodeStatistics(_make(), gamma=0.99), weight=weights)
    env.reset(seed=1)
    total = np.zeros(5)
    done = False
    while not done:
        _, r, terminated, truncated, info = env.step(np.array([0.5], dtype=np.float32))
        assert np.isclose(r, float(np.dot(weights, info["vector_reward"])), atol=1e-5)
        total += info["vector_reward"]
        done = terminated or truncated
    episode = info["episode"]
    assert episode["r"].shape == (5,)
    np.testing.assert_allclose(episode["r"], total, rtol=1e-5, atol=1e-5)
    env.close()


def test_mo_sync_vector_env_autoresets_and_records_vector_returns():
    venv = VecMORecordEpisodeStatistics(MOSyncVectorEnv([_make for _ in range(2)]), gamma=0.99)
    venv.reset(seed=[0, 1])
    finished = False
    for _ in range(200):
        _, rewards, terminated, truncated, infos = venv.step(np.full((2, 1), 0.5, dtype=np.float32))
        assert rewards.shape == (2, 5)
        if np.any(terminated | truncated):
            finished = True
            assert "episode" in infos
            assert np.asarray(infos["episode"]["r"]).shape == (2, 5)
            break
    assert finished
    venv.close()


def test_scalar_mode_is_not_an_mo_env_and_mo_wrappers_refuse_it():
    env = mog.make(ENV_ID, race={"duration": 3.0})  # scalar mode (the default)
    assert not hasattr(env.unwrapped, "reward_space")
    with pytest.raises(AttributeError, match="reward_mode='vector'"):
        LinearReward(env, weight=np.ones(5))
    env.close()


def test_linear_reward_through_mo_gymnasium_scalarises_the_real_vector():
    weights = np.array([10.0, 1.0, 0.05, 0.5, 0.1])
    env = LinearReward(mog.make(ENV_ID, reward_mode="vector", race={"duration": 3.0}), weight=weights)
    scalar = mog.make(ENV_ID, race={"duration": 3.0})
    env.reset(seed=2)
    scalar.reset(seed=2)
    for _ in range(5):
        _, r, *_, info = env.step(np.array([0.5], np.float32))
        _, s, *_ = scalar.step(np.array([0.5], np.float32))
        assert info["vector_reward"].shape == (5,) and np.count_nonzero(info["vector_reward"] == s) < 5
        assert r == pytest.approx(s, rel=1e-5, abs=1e-6)  # the env's own scalar is the same weighted sum
    env.close()
    scalar.close()


def test_make_vec_in_vector_mode_returns_mo_gymnasium_vector_env():
    import gymnasium as gym

    venv = gym.make_vec(ENV_ID, num_envs=2, reward_mode="vector", race={"duration": 3.0})
    assert isinstance(venv, MOSyncVectorEnv) and venv.reward_space.shape == (5,)
    venv.reset(seed=[0, 1])
    _, rewards, _, _, infos = venv.step(np.full((2, 1), 0.5, dtype=np.float32))
    assert rewards.shape == (2, 5) and rewards.dtype == np.float32
    np.testing.assert_array_equal(rewards, infos["reward_vector"])
    venv.close()


def test_make_vec_in_scalar_mode_is_gymnasium_sync_vector_env():
    import gymnasium as gym

    venv = gym.make_vec(ENV_ID, num_envs=2, race={"duration": 3.0})
    assert type(venv) is gym.vector.SyncVectorEnv and venv.envs[0].spec.id == ENV_ID
    one = gym.make(ENV_ID, race={"duration": 3.0})
    venv.reset(seed=[5, 6])
    one.reset(seed=5)
    for _ in range(3):
        _, rewards, *_ = venv.step(np.full((2, 1), 0.5, dtype=np.float32))
        _, r, *_ = one.step(np.array([0.5], np.float32))
        assert rewards.shape == (2,) and rewards[0] == r
    venv.close()
    one.close()
