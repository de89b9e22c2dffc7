"""Several SOfAR cars in one race through the PettingZoo parallel API, each choosing its own gamma.

    python examples/pettingzoo_parallel.py
"""

from __future__ import annotations

import numpy as np

from _common import max_steps, race_seconds
from sofar_env.multi_agent import parallel_env


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
