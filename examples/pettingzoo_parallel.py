"""Several SOfAR cars in one race through the PettingZoo parallel API, each choosing its own gamma.

    python examples/pettingzoo_parallel.py
"""

from __future__ import annotations

import os

import numpy as np

from sofar_env.multi_agent import parallel_env

# SOFAR_EXAMPLE_STEPS=N (the smoke tests set it) caps every loop at N steps and the race at 3 s
SMOKE_STEPS = os.environ.get("SOFAR_EXAMPLE_STEPS")


def max_steps(default: int) -> int:
    return int(SMOKE_STEPS) if SMOKE_STEPS else default


def race_seconds(default: float) -> float:
    return 3.0 if SMOKE_STEPS else default


def main() -> None:
    env = parallel_env(track="LagunaSeca", n_agents=2, config={"race": {"duration": race_seconds(20.0)}})
    observations, infos = env.reset(seed=0)
    returns = {agent: 0.0 for agent in env.agents}
    for _ in range(max_steps(10_000)):
        actions = {agent: np.array([0.3], dtype=np.float32) for agent in env.agents}
        observations, rewards, terminations, truncations, infos = env.step(actions)
        for agent, r in rewards.items():
            returns[agent] += r
        if not env.agents:
            break
    env.close()
    print("returns:", returns)


if __name__ == "__main__":
    main()
