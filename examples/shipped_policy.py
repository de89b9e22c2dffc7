"""Race with the shipped PASTA policy (trained on Laguna Seca) choosing gamma.

    python examples/shipped_policy.py
"""

from __future__ import annotations

import os

import gymnasium as gym

import sofar_agents
import sofar_env  # noqa: F401  (registers the SOfAR ids)

# SOFAR_EXAMPLE_STEPS=N (the smoke tests set it) caps every loop at N steps and the race at 3 s
SMOKE_STEPS = os.environ.get("SOFAR_EXAMPLE_STEPS")


def max_steps(default: int) -> int:
    return int(SMOKE_STEPS) if SMOKE_STEPS else default


def race_seconds(default: float) -> float:
    return 3.0 if SMOKE_STEPS else default


def main() -> None:
    policy = sofar_agents.load_policy(sofar_agents.default_policy_path())
    env = gym.make("SOfAR-LagunaSeca-v0", config={"race": {"duration": race_seconds(60.0)}})
    obs, info = env.reset(seed=0)
    gammas = []
    for _ in range(max_steps(100_000)):
        action = policy(obs)
        gammas.append(float(action[0]))
        obs, reward, terminated, truncated, info = env.step(action)
        if terminated or truncated:
            break
    env.close()
    print(f"{len(gammas)} decisions, mean gamma {sum(gammas) / len(gammas):.3f}, "
          f"overtakes {info.get('overtakes')}, collision {info.get('collision')}")


if __name__ == "__main__":
    main()
