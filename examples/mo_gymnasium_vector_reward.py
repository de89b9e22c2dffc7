"""The five-objective reward vector through MO-Gymnasium: ``mo_gymnasium.make``, its wrappers and vector envs.

    python examples/mo_gymnasium_vector_reward.py

``reward_mode="vector"`` returns a float32 vector declared in ``env.unwrapped.reward_space``. Make it with
``mo_gymnasium.make`` (``gymnasium.make`` without the passive checker, which expects scalar rewards) and
vectorise it with ``MOSyncVectorEnv`` (``gymnasium.vector.SyncVectorEnv`` stores scalar rewards only).
"""

from __future__ import annotations

import os

import mo_gymnasium as mog
import numpy as np
from mo_gymnasium.wrappers import LinearReward, MORecordEpisodeStatistics
from mo_gymnasium.wrappers.vector import MOSyncVectorEnv

import sofar_env  # noqa: F401  (registers the SOfAR ids)

# SOFAR_EXAMPLE_STEPS=N (the smoke tests set it) caps every loop at N steps and the race at 3 s
SMOKE_STEPS = os.environ.get("SOFAR_EXAMPLE_STEPS")


def max_steps(default: int) -> int:
    return int(SMOKE_STEPS) if SMOKE_STEPS else default


def race_seconds(default: float) -> float:
    return 3.0 if SMOKE_STEPS else default


CONFIG = {"reward_mode": "vector", "race": {"duration": race_seconds(20.0)}}


def main() -> None:
    steps = max_steps(10_000)

    # one env: episode statistics of the vector, then a weighted scalar
    weights = np.array([0.31, 0.45, 0.05, 0.04, 0.15])
    env = LinearReward(MORecordEpisodeStatistics(mog.make("SOfAR-LagunaSeca-v0", config=CONFIG), gamma=0.99),
                       weight=weights)
    env.reset(seed=0)
    for _ in range(steps):
        _, scalar, terminated, truncated, info = env.step(np.array([0.4], dtype=np.float32))
        if terminated or truncated:
            print("episode vector return:", info["episode"]["r"])
            break
    print("last scalar reward", float(scalar), "from", info["vector_reward"])
    env.close()

    # two envs in a vector env: rewards of shape (n_envs, n_objectives)
    venv = MOSyncVectorEnv([lambda: mog.make("SOfAR-LagunaSeca-v0", config=CONFIG) for _ in range(2)])
    venv.reset(seed=0)
    total = np.zeros((2, 5))
    for _ in range(min(steps, 20)):
        _, rewards, _, _, _ = venv.step(venv.action_space.sample())
        total += rewards
    venv.close()
    print("summed vector rewards per env:\n", total)


if __name__ == "__main__":
    main()
