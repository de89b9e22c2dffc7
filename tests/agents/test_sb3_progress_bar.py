"""Stable-Baselines3's own progress bar (``learn(progress_bar=True)``) works: its ``rich`` dependency is one of ours."""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import pytest

import sofar_env  # noqa: F401  (registers the ids)
from sofar_agents.wrappers import RescaleGammaAction

ROOT = Path(__file__).resolve().parents[2]


def test_rich_is_a_dependency() -> None:
    tomllib = pytest.importorskip("tomllib")  # Python >= 3.11
    deps = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["dependencies"]
    assert any(d.split(">")[0].split("=")[0].strip() == "rich" for d in deps)


def test_sb3_learns_with_its_progress_bar() -> None:
    from stable_baselines3 import PPO

    env = RescaleGammaAction(gym.make("SOfAR-LagunaSeca-v0", race={"duration": 2.0}))
    model = PPO("MlpPolicy", env, n_steps=16, batch_size=16, n_epochs=1, seed=0, device="cpu")
    model.learn(total_timesteps=16, progress_bar=True)
    assert model.num_timesteps == 16
    env.close()
