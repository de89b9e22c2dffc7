"""Race with a fixed barrier decay gamma, then with a random gamma at every decision.

    python examples/fixed_and_random_gamma.py
"""

from __future__ import annotations

import os

import gymnasium as gym
import numpy as np

import sofar_env  # noqa: F401  (registers the SOfAR ids)

# SOFAR_EXAMPLE_STEPS=N (the smoke tests set it) caps every loop at N steps and the race at 3 s
SMOKE_STEPS = os.environ.get("SOFAR_EXAMPLE_STEPS")


def max_steps(default: int) -> int:
    return int(SMOKE_STEPS) if SMOKE_STEPS else default


def race_seconds(default: float) -> float:
    return 3.0 if SMOKE_STEPS else default


def run(env: gym.Env, choose, steps: int, seed: int = 0) -> dict:
    obs, info = env.reset(seed=seed)
    total = 0.0
    for _ in range(steps):
        obs, reward, terminated, truncated, info = env.step(choose(obs))
        total += reward
        if terminated or truncated:
            break
    return {"return": total, "overtakes": info.get("overtakes"), "collision": info.get("collision")}


def main() -> None:
    env = gym.make("SOfAR-LagunaSeca-v0", config={"race": {"duration": race_seconds(30.0)}})
    steps = max_steps(10_000)
    fixed = run(env, lambda obs: np.array([0.3], dtype=np.float32), steps)
    env.action_space.seed(0)
    random = run(env, lambda obs: env.action_space.sample(), steps)
    env.close()
    print(f"fixed gamma 0.3: {fixed}")
    print(f"random gamma:    {random}")


if __name__ == "__main__":
    main()
