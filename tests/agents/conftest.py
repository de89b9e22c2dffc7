"""Fixtures shared by the agent tests."""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import pytest
import torch

from sofar_agents import PASTA, PASTAConfig
from sofar_agents.wrappers import LinearReward
from synthetic_envs import OBJECTIVES, PREF, SyntheticRace


@pytest.fixture(scope="session")
def trained(tmp_path_factory: pytest.TempPathFactory) -> tuple[PASTA, Path]:
    """A PASTA agent after two small updates on the synthetic race, saved to disk."""
    torch.set_num_threads(1)
    venv = gym.vector.SyncVectorEnv([lambda: LinearReward(SyntheticRace())],
                                    autoreset_mode=gym.vector.AutoresetMode.SAME_STEP)
    config = PASTAConfig(n_steps=64, n_epochs=2, hidden_sizes=(64, 64), critic_head_hidden=16, pcgrad=True)
    agent = PASTA(12, 5, [0.05], [1.0], config, preference=PREF, seed=7, objective_names=OBJECTIVES)
    agent.learn(venv, 128)
    venv.close()
    path = agent.save(tmp_path_factory.mktemp("ckpt") / "agent", metadata={"command": "test", "seed": 7})
    return agent, path
