"""Small synthetic environments for the agent tests (no simulator needed).

- :class:`NonConvexBandit`: one-step, two objectives whose Pareto front is concave-in
  (non-convex), so linear scalarisation only ever selects an extreme point.
- :class:`SyntheticRace`: a cheap stand-in for the SOfAR environment contract
  (12-dim observation, action gamma in [0.05, 1], five named objectives, ``reward_mode``,
  ``rho``, ``decision_interval``, the usual info keys). Registered on import as
  ``SOfARTest/SyntheticRace-v0``; usable from another process as
  ``synthetic_envs:SOfARTest/SyntheticRace-v0`` when this folder is on the path.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

OBJECTIVES = ("safety", "overtakes", "progress", "barrier_margin", "gamma_smoothness")
PREF = (0.31, 0.45, 0.05, 0.04, 0.15)
"""The reference deployment preference over :data:`OBJECTIVES`."""


def bandit_rewards(a: float | np.ndarray) -> np.ndarray:
    """``(f1, f2) = (a, (1 - a)^3)``: f1 linear, f2 convex, so every positive weighted
    sum is convex in a and maximised at a = 0 or a = 1, while the balanced point
    (f1 = f2 at a ~ 0.32) sits in the dent of the front."""
    a = np.asarray(a, dtype=np.float64)
    return np.stack([a, (1.0 - a) ** 3], axis=-1)


class NonConvexBandit(gym.Env):
    """One-step bandit with a two-objective reward vector ``bandit_rewards(a)``."""

    metadata: dict[str, Any] = {"render_modes": []}

    def __init__(self, reward_mode: str = "vector", reward_weights: Any = None) -> None:
        self.observation_space = gym.spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)
        self.action_space = gym.spaces.Box(0.0, 1.0, shape=(1,), dtype=np.float32)
        self.reward_space = gym.spaces.Box(0.0, 1.0, shape=(2,), dtype=np.float32)
        self.objective_names = ("f1", "f2")
        self.reward_mode = reward_mode
        self.reward_weights = np.ones(2) if reward_weights is None else np.asarray(reward_weights, float)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        return np.zeros(2, dtype=np.float32), {}

    def step(self, action: Any):
        a = float(np.clip(np.asarray(action).reshape(-1)[0], 0.0, 1.0))
        vec = bandit_rewards(a).astype(np.float32)
        reward = vec if self.reward_mode == "vector" else float(self.reward_weights @ vec)
        return np.zeros(2, dtype=np.float32), reward, True, False, {"reward_vector": vec}


class SyntheticRace(gym.Env):
    """Cheap stand-in for ``SOfAR-*-v0``: larger gamma -> more overtakes and more crashes.

    Each step the ego closes on an opponent; an overtake happens with probability
    ``0.3 * gamma * (1 - rho)`` and a collision (termination) with probability
    ``0.03 * gamma^2``. Episodes are truncated after ``max_steps`` steps.
    """

    metadata: dict[str, Any] = {"render_modes": []}

    def __init__(self, reward_mode: str = "vector", rho: float = 0.5, decision_interval: int = 5,
                 max_steps: int = 40, reward_weights: Any = None) -> None:
        self.observation_space = gym.spaces.Box(-1.0, 1.0, shape=(12,), dtype=np.float32)
        self.action_space = gym.spaces.Box(np.array([0.05], np.float32), np.array([1.0], np.float32))
        self.reward_space = gym.spaces.Box(-np.inf, np.inf, shape=(5,), dtype=np.float32)
        self.objective_names = OBJECTIVES
        self.reward_mode = reward_mode
        self.rho = float(rho)
        self.decision_interval = int(decision_interval)
        self.max_steps = int(max_steps)
        self.reward_weights = np.ones(5) if reward_weights is None else np.asarray(reward_weights, float)

    def _obs(self) -> np.ndarray:
        o = self.np_random.uniform(-1.0, 1.0, size=12).astype(np.float32)
        o[0] = self.rho
        o[1] = self._t / self.max_steps
        return o

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        if options and "rho" in options:
            self.rho = float(options["rho"])
        self._t, self._overtakes, self._gamma = 0, 0, 0.5
        return self._obs(), {"rho": self.rho}

    def step(self, action: Any):
        gamma = float(np.asarray(action).reshape(-1)[0])
        if not np.isfinite(gamma):
            raise ValueError(f"non-finite action {action}")
        gamma = min(max(gamma, 0.05), 1.0)
        self._t += 1
        overtake = self.np_random.random() < 0.3 * gamma * (1.0 - self.rho)
        collision = self.np_random.random() < 0.03 * gamma**2
        self._overtakes += int(overtake)
        vec = np.array([-float(collision), float(overtake), 0.01 * gamma, -0.01 * gamma,
                        -(gamma - self._gamma) ** 2], dtype=np.float32)
        self._gamma = gamma
        terminated = bool(collision)
        truncated = self._t >= self.max_steps and not terminated
        info: dict[str, Any] = {"reward_vector": vec, "overtakes": self._overtakes, "laps": self._t / 20.0,
                                "collision": bool(collision), "off_track": False}
        if terminated or truncated:
            info["is_success"] = not terminated
        reward = vec if self.reward_mode == "vector" else float(self.reward_weights @ vec)
        return self._obs(), reward, terminated, truncated, info


if "SOfARTest/SyntheticRace-v0" not in gym.registry:
    gym.register("SOfARTest/SyntheticRace-v0", entry_point=SyntheticRace)
if "SOfARTest/NonConvexBandit-v0" not in gym.registry:
    gym.register("SOfARTest/NonConvexBandit-v0", entry_point=NonConvexBandit)
