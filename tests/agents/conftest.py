"""Fixtures shared by the agent tests."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from types import ModuleType

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


@pytest.fixture(scope="session")
def training_env_script() -> ModuleType:
    """``eval/training_env.py`` as a module (its ``record_single``, ``record_race``, ``main``)."""
    path = Path(__file__).resolve().parents[2] / "eval" / "training_env.py"
    spec = importlib.util.spec_from_file_location("eval_training_env", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module
