"""Train Stable-Baselines3 PPO on the scalar reward for a few hundred steps and evaluate it.

    python examples/sb3_ppo.py

For full training runs use ``train/ppo.py``.
"""

from __future__ import annotations

import os

import gymnasium as gym
from stable_baselines3 import PPO

import sofar_env  # noqa: F401  (registers the SOfAR ids)
from sofar_agents.wrappers import RescaleGammaAction

# SOFAR_EXAMPLE_STEPS=N (the smoke tests set it) caps every loop at N steps and the race at 3 s
SMOKE_STEPS = os.environ.get("SOFAR_EXAMPLE_STEPS")


def max_steps(default: int) -> int:
    return int(SMOKE_STEPS) if SMOKE_STEPS else default


def race_seconds(default: float) -> float:
    return 3.0 if SMOKE_STEPS else default


def main() -> None:
    steps = max(max_steps(512), 64)
    # PPO's Gaussian policy assumes a [-1, 1] box; the wrapper maps it onto gamma in [0.05, 1]
    env = RescaleGammaAction(gym.make("SOfAR-LagunaSeca-v0", config={"race": {"duration": race_seconds(20.0)}}))
    model = PPO("MlpPolicy", env, n_steps=64, batch_size=32, n_epochs=2, seed=0, verbose=0, device="cpu")
    model.learn(total_timesteps=steps)
    obs, _ = env.reset(seed=1)
    total = 0.0
    for _ in range(steps):
        action, _ = model.predict(obs, deterministic=True)
        obs, reward, terminated, truncated, info = env.step(action)
        total += reward
        if terminated or truncated:
            break
    env.close()
    print(f"trained {steps} steps; evaluation return {total:.3f}")


if __name__ == "__main__":
    main()
