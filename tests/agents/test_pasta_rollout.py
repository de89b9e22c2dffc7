"""Rollout collection: bootstrap targets, episode records, reward vectors and the autoreset check."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import pytest
import torch

from sofar_agents import PASTA, PASTAConfig
from sofar_agents.pasta.rollout import reward_vectors
from sofar_agents.wrappers import LinearReward
from synthetic_envs import SyntheticRace


class _EpisodeEnv(gym.Env):
    """Deterministic episodes: even ones terminate after 2 steps, odd ones are truncated after 3."""

    def __init__(self) -> None:
        self.observation_space = gym.spaces.Box(-10, 10, shape=(2,), dtype=np.float32)
        self.action_space = gym.spaces.Box(np.array([0.05], np.float32), np.array([1.0], np.float32))
        self.reward_space = gym.spaces.Box(-1, 1, shape=(2,), dtype=np.float32)
        self._episode = -1

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        self._episode += 1
        self._t = 0
        return np.array([self._episode, 0.0], np.float32), {}

    def step(self, action: Any):
        self._t += 1
        obs = np.array([self._episode, self._t], np.float32)
        terminated = self._episode % 2 == 0 and self._t == 2
        truncated = self._episode % 2 == 1 and self._t == 3
        return obs, np.array([1.0, -0.5], np.float32), terminated, truncated, {}


def test_rollout_bootstrap_targets() -> None:
    torch.set_num_threads(1)
    venv = gym.vector.SyncVectorEnv([lambda: LinearReward(_EpisodeEnv())],
                                    autoreset_mode=gym.vector.AutoresetMode.SAME_STEP)
    agent = PASTA(2, 2, [0.05], [1.0], PASTAConfig(hidden_sizes=(16,), critic_head_hidden=0,
                                                   preference_sampling="fixed"), seed=3)
    buf = agent.collect(venv, 9)  # episodes: term at t=1, trunc at t=4, term at t=6, last partial
    term, trunc = buf.terminated[:, 0], buf.truncated[:, 0]
    np.testing.assert_array_equal(np.flatnonzero(term), [1, 6])
    np.testing.assert_array_equal(np.flatnonzero(trunc), [4])
    np.testing.assert_allclose(buf.rewards[:, 0], np.tile([1.0, -0.5], (9, 1)))

    def value(obs: list[float]) -> np.ndarray:
        x = torch.as_tensor([[*obs, *agent.preference]], dtype=torch.float32)
        with torch.no_grad():
            return agent.critic(x).numpy()[0]

    nv = buf.next_values[:, 0]
    np.testing.assert_allclose(nv[1], 0.0)  # terminated
    np.testing.assert_allclose(nv[6], 0.0)
    np.testing.assert_allclose(nv[4], value([1.0, 3.0]), rtol=1e-5)  # V(final_obs) of episode 1
    for t in (0, 2, 3, 5, 7):  # inside an episode: the next stored value
        np.testing.assert_allclose(nv[t], buf.values[t + 1, 0])
    np.testing.assert_allclose(nv[8], value([3.0, 2.0]), rtol=1e-5)  # V(last_obs)
    venv.close()


def test_rollout_episode_records_and_timesteps() -> None:
    torch.set_num_threads(1)
    venv = gym.vector.SyncVectorEnv([lambda: LinearReward(_EpisodeEnv())],
                                    autoreset_mode=gym.vector.AutoresetMode.SAME_STEP)
    agent = PASTA(2, 2, [0.05], [1.0], PASTAConfig(hidden_sizes=(8,), critic_head_hidden=0), seed=3)
    buf = agent.collect(venv, 9)
    assert agent.num_timesteps == 9
    assert [e["length"] for e in buf.episodes] == [2, 3, 2]
    np.testing.assert_allclose(buf.episodes[1]["returns"], [3.0, -1.5])
    assert len(agent.ep_info_buffer) == 3
    # The next rollout continues the unfinished episode (no reset): its first step ends it.
    buf2 = agent.collect(venv, 1)
    assert agent.num_timesteps == 10 and [e["length"] for e in buf2.episodes] == [3]
    venv.close()


def test_reward_vectors() -> None:
    done = np.array([False, True])
    r = np.arange(4.0).reshape(2, 2)
    np.testing.assert_array_equal(reward_vectors(r, {}, done, 2), r)  # already vectors
    np.testing.assert_array_equal(reward_vectors(np.array([1.0, 2.0]), {}, done, 1), [[1.0], [2.0]])
    infos = {"reward_vector": np.array([[1.0, 2.0], [9.0, 9.0]]), "_reward_vector": np.array([True, False]),
             "final_info": {"reward_vector": np.array([[0.0, 0.0], [3.0, 4.0]]),
                            "_reward_vector": np.array([False, True])}}
    # env 0 from the step info, env 1 (done) from its final info
    np.testing.assert_array_equal(reward_vectors(np.zeros(2), infos, done, 2), [[1.0, 2.0], [3.0, 4.0]])
    with pytest.raises(ValueError, match="LinearReward"):
        reward_vectors(np.zeros(2), {}, done, 2)


def test_collect_requires_same_step_autoreset() -> None:
    venv = gym.vector.SyncVectorEnv([lambda: LinearReward(SyntheticRace())])  # NEXT_STEP default
    agent = PASTA(12, 5, [0.05], [1.0], PASTAConfig(hidden_sizes=(8,), critic_head_hidden=0))
    with pytest.raises(ValueError, match="SAME_STEP"):
        agent.collect(venv, 4)
    venv.close()
