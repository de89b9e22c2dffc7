"""Gymnasium wrappers used to train on the SOfAR environments.

- :class:`LinearReward`: vector reward -> weighted scalar (MO-Gymnasium convention),
  keeping the vector in ``info["reward_vector"]`` (see its docstring for when to use
  ``mo_gymnasium.wrappers.LinearReward`` instead). Also what lets a
  ``gymnasium.vector.SyncVectorEnv`` carry vector rewards (it stores scalar rewards).
- :class:`RescaleGammaAction`: policy actions in ``[-1, 1]`` -> gamma in ``[0.05, 1]``
  (for Stable-Baselines3, whose Gaussian policies assume a symmetric unit box).
- :class:`RandomRhoReset`: samples the opponent pace ratio rho for every episode and
  passes it through ``reset(options={"rho": ...})``.
"""

from __future__ import annotations

from typing import Any, Sequence

import gymnasium as gym
import numpy as np

from sofar_env.constants import RHOS

__all__ = ["LinearReward", "RescaleGammaAction", "RandomRhoReset", "EVAL_RHOS"]

EVAL_RHOS = RHOS
"""Opponent pace ratios of the paper's evaluation."""


class LinearReward(gym.Wrapper):
    """Scalarise a vector reward with fixed weights: ``r = weights . r_vec``.

    The original vector is stored in ``info["reward_vector"]`` (a copy). ``weights``
    default to ones (plain sum). The number of objectives is taken from
    ``env.unwrapped.reward_space`` when the env declares one.

    For the SOfAR envs prefer the maintained ``mo_gymnasium.wrappers.LinearReward``
    (as ``train/ppo.py`` does). This one is kept because PASTA's rollout collector
    (:mod:`sofar_agents.pasta.rollout`) reads the vector from ``info["reward_vector"]``,
    which this wrapper guarantees for any vector-reward env (the SOfAR envs also set it
    themselves; MO-Gymnasium's wrapper writes ``info["vector_reward"]``), and because it also wraps envs that
    declare no ``reward_space`` when ``weights`` are given, returns a Python ``float``,
    leaves the wrapped env's ``info`` dict unmodified and reports bad weights with
    ``ValueError`` rather than an ``assert``.
    """

    def __init__(self, env: gym.Env, weights: Sequence[float] | np.ndarray | None = None) -> None:
        super().__init__(env)
        space = getattr(env.unwrapped, "reward_space", None)
        k = int(np.prod(space.shape)) if space is not None else None
        if weights is None:
            if k is None:
                raise ValueError("weights are required when the env declares no reward_space")
            weights = np.ones(k)
        self.weights = np.asarray(weights, dtype=np.float64).reshape(-1)
        if k is not None and self.weights.shape != (k,):
            raise ValueError(f"{self.weights.shape[0]} weights for a reward space of {k} objectives")

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        obs, reward, terminated, truncated, info = self.env.step(action)
        vec = np.asarray(reward, dtype=np.float32).reshape(-1)
        if vec.shape != self.weights.shape:
            raise ValueError(f"reward of shape {np.shape(reward)} for {self.weights.shape[0]} weights")
        info = dict(info)
        info["reward_vector"] = vec.copy()
        return obs, float(np.dot(self.weights, vec)), terminated, truncated, info


class RescaleGammaAction(gym.ActionWrapper):
    """Expose ``Box(-1, 1)`` and map affinely onto the env's gamma box (``[0.05, 1]``).

    Actions outside ``[-1, 1]`` are clipped first; non-finite actions raise ``ValueError``.
    """

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        space = env.action_space
        if not isinstance(space, gym.spaces.Box) or not np.all(np.isfinite(space.low)) or not np.all(
            np.isfinite(space.high)
        ):
            raise ValueError(f"RescaleGammaAction needs a bounded Box action space, got {space}")
        self._low = space.low.astype(np.float32)
        self._high = space.high.astype(np.float32)
        self.action_space = gym.spaces.Box(-1.0, 1.0, shape=space.shape, dtype=np.float32)

    def action(self, action: Any) -> np.ndarray:
        a = np.asarray(action, dtype=np.float32).reshape(self._low.shape)
        if not np.all(np.isfinite(a)):
            raise ValueError(f"non-finite action {action}")
        a = np.clip(a, -1.0, 1.0)
        return np.clip(self._low + (a + 1.0) * 0.5 * (self._high - self._low), self._low, self._high)


class RandomRhoReset(gym.Wrapper):
    """Draw the opponent pace ratio rho per episode and pass it as ``options["rho"]``.

    rho is drawn uniformly from ``values`` when given, otherwise uniformly from
    ``[low, high]``. An explicit ``options["rho"]`` given to ``reset`` wins. The
    wrapper owns its generator; a seeded ``reset(seed=s)`` reseeds it from an
    independent stream derived from ``s``, so runs are reproducible.
    """

    def __init__(self, env: gym.Env, low: float = 0.1, high: float = 0.8,
                 values: Sequence[float] | None = None) -> None:
        super().__init__(env)
        if values is not None and len(values) == 0:
            raise ValueError("values must not be empty")
        if values is None and not 0.0 < low <= high:
            raise ValueError(f"need 0 < low <= high, got {low}, {high}")
        self.low, self.high = float(low), float(high)
        self.values = None if values is None else tuple(float(v) for v in values)
        self._rho_rng = np.random.default_rng()

    def sample_rho(self) -> float:
        if self.values is not None:
            return self.values[int(self._rho_rng.integers(len(self.values)))]
        return float(self._rho_rng.uniform(self.low, self.high))

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict]:
        if seed is not None:
            self._rho_rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0x52484F]))
        options = dict(options or {})
        options.setdefault("rho", self.sample_rho())
        return self.env.reset(seed=seed, options=options)
