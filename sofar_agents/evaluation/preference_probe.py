"""Does a preference-conditioned agent's preference move its action? A fast, controlled test bed.

:class:`TradeoffEnv` is a small Gymnasium environment with the racing world's trade-off and none of its
cost: one action (the barrier decay gamma in ``[0.05, 1]``) per step, and a reward vector of the same five
objectives as the SOfAR environments (safety, overtakes, progress, barrier margin, gamma smoothness).
A per-episode traffic density ``d`` in ``[0, 1]`` is observed; per step the car crashes with probability
``d * (crash_base + crash_slope * gamma)`` (safety -1, episode over) and overtakes with probability
``d * overtake_rate * sqrt(gamma)``. A bold gamma overtakes more and crashes more, as in the dense
interactive world, so a preference that weighs safety should choose a lower gamma than one that weighs
overtakes; which gamma is best for a preference is known in closed form (:meth:`TradeoffEnv.expected_returns`).

:func:`preference_response` reads a trained agent: its deterministic action at each of a set of preferences,
over a set of observations (mean and spread per preference). Both serve ``eval/pasta_preference.py``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np

__all__ = ["PROBE_VARIANTS", "PROBE_SAFETY_WEIGHTS", "ProbeResult", "PreferenceResponse", "TradeoffEnv",
           "preference_response", "probe_observations", "run_probe", "safety_preferences"]

OTHER_WEIGHT = 0.1
"""Weight kept on progress, barrier margin and gamma smoothness together by :func:`safety_preferences`
(the convention of ``eval/pareto.py``)."""


def safety_preferences(safety_weights: Sequence[float], n_objectives: int = 5) -> np.ndarray:
    """Preferences ``(safety w, overtakes 0.9 - w, 0.1 / 3 each for the rest)``, one row per weight."""
    rows = []
    for w in safety_weights:
        if not 0.0 <= w <= 1.0 - OTHER_WEIGHT:
            raise ValueError(f"safety weight {w} outside [0, {1.0 - OTHER_WEIGHT}]")
        rest = [OTHER_WEIGHT / (n_objectives - 2)] * (n_objectives - 2)
        rows.append([w, 1.0 - OTHER_WEIGHT - w, *rest])
    return np.asarray(rows, dtype=np.float64)


class TradeoffEnv(gym.Env):
    """One gamma per step; reward vector ``(safety, overtakes, progress, barrier margin, gamma smoothness)``.

    Observation ``(d, t / horizon, previous gamma, 0)`` in ``[-1, 1]^4`` (``d`` scaled to ``2 d - 1``).
    The scalar reward is the sum of the vector; the vector is ``info["reward_vector"]``. The episode ends
    (terminated) on a crash and is truncated after ``horizon`` steps.
    """

    metadata = {"render_modes": []}

    def __init__(self, horizon: int = 100, crash_base: float = 0.0005, crash_slope: float = 0.004,
                 overtake_rate: float = 0.1) -> None:
        if horizon < 1 or min(crash_base, crash_slope, overtake_rate) < 0:
            raise ValueError("horizon must be >= 1 and the rates non-negative")
        if crash_base + crash_slope > 1.0 or overtake_rate > 1.0:
            raise ValueError("per-step probabilities must stay <= 1")
        self.horizon, self.crash_base, self.crash_slope = int(horizon), crash_base, crash_slope
        self.overtake_rate = overtake_rate
        self.observation_space = gym.spaces.Box(-1.0, 1.0, (4,), np.float32)
        self.action_space = gym.spaces.Box(np.float32(0.05), np.float32(1.0), (1,), np.float32)
        self._d, self._t, self._prev = 0.5, 0, 0.05

    def _obs(self) -> np.ndarray:
        return np.array([2.0 * self._d - 1.0, self._t / self.horizon, self._prev, 0.0], np.float32)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        self._d, self._t, self._prev = float(self.np_random.uniform()), 0, 0.05
        return self._obs(), {}

    def step(self, action: Any):
        g = float(np.clip(np.asarray(action, dtype=np.float64).reshape(-1)[0], 0.05, 1.0))
        crash = self.np_random.uniform() < self._d * (self.crash_base + self.crash_slope * g)
        overtake = self.np_random.uniform() < self._d * self.overtake_rate * math.sqrt(g)
        vec = np.array([-1.0 if crash else 0.0, float(overtake), 0.8 + 0.1 * g, -0.02 * g, -abs(g - self._prev)])
        self._prev, self._t = g, self._t + 1
        truncated = self._t >= self.horizon and not crash
        return self._obs(), float(vec.sum()), bool(crash), truncated, {"reward_vector": vec}

    def expected_returns(self, gamma: float, d: float) -> np.ndarray:
        """Expected undiscounted episode returns of a constant ``gamma`` at density ``d`` (the first step's
        smoothness term included)."""
        p = d * (self.crash_base + self.crash_slope * gamma)
        alive = (1.0 - p) ** np.arange(self.horizon)  # probability of starting step t
        steps = alive.sum()
        return np.array([-(1.0 - (1.0 - p) ** self.horizon), steps * d * self.overtake_rate * math.sqrt(gamma),
                         steps * (0.8 + 0.1 * gamma), -steps * 0.02 * gamma, -abs(gamma - 0.05)])


@dataclass(frozen=True)
class PreferenceResponse:
    """The deterministic action of a policy per preference over a set of observations."""

    preferences: np.ndarray
    """``(P, K)``."""
    mean: np.ndarray
    """Mean action per preference ``(P,)``."""
    p10: np.ndarray
    p90: np.ndarray

    @property
    def spread(self) -> float:
        """Largest minus smallest mean action over the preferences."""
        return float(self.mean.max() - self.mean.min())

    def monotone(self, decreasing: bool = True) -> bool:
        """Whether the mean action moves monotonically (non-strictly) along the preferences."""
        d = np.diff(self.mean)
        return bool(np.all(d <= 1e-9) if decreasing else np.all(d >= -1e-9))


def preference_response(agent: Any, observations: np.ndarray, preferences: np.ndarray) -> PreferenceResponse:
    """``agent.predict(obs, deterministic=True, preference=w)`` for each preference row over all observations."""
    obs = np.asarray(observations, dtype=np.float32)
    means, lo, hi = [], [], []
    for w in np.asarray(preferences, dtype=np.float64):
        a = np.asarray(agent.predict(obs, deterministic=True, preference=w), dtype=np.float64).reshape(len(obs), -1)
        means.append(a[:, 0].mean())
        lo.append(np.percentile(a[:, 0], 10))
        hi.append(np.percentile(a[:, 0], 90))
    return PreferenceResponse(np.asarray(preferences, dtype=np.float64), np.array(means), np.array(lo), np.array(hi))


SHIPPED_RECIPE: dict[str, Any] = {"action_squashing": "clip", "initial_action": 0.08, "log_std_init": -2.3,
                                  "mu_max": 10.0, "n_steps": 1024, "batch_size": 256, "conflict_every": 8}
"""The training settings of the shipped dense-interactive policy (its ``--action-squashing clip
--initial-action 0.08 --log-std-init -2.3 --n-steps 1024 --batch-size 256``; the conflict is measured on
every 8th minibatch only, which shortens an update and changes nothing else) and the reference's attention
temperature, ``mu_max = 10``, that it was trained with."""

MID_START: dict[str, Any] = {"initial_action": 0.5, "log_std_init": -1.2}
"""Start in the middle of the gamma range with a spread of 0.3 (instead of 0.08 and 0.1)."""

CAUTIOUS_START: dict[str, Any] = {"initial_action": 0.15, "log_std_init": -1.2}
"""Start near the cautious end of the gamma range, at 0.15, with a spread of 0.3."""

TRADE_OFF: dict[str, Any] = {"preference_sampling": "trade-off", "preference": (0.5, 0.4) + (OTHER_WEIGHT / 3,) * 3}
"""Preferences drawn uniformly along the safety-overtakes path that :func:`safety_preferences` reads (the
preference the path starts from is the run's preference)."""

PROBE_VARIANTS: dict[str, dict[str, Any]] = {
    "shipped": {},
    "linear": {"scalarization": "linear"},
    "mu 0.1": {"fixed_mu": 0.1},
    "mid start": dict(MID_START),
    "linear, mid start": {"scalarization": "linear", **MID_START},
    "mu 0.1, mid start": {"fixed_mu": 0.1, **MID_START},
    "mu 0.3, mid start": {"fixed_mu": 0.3, **MID_START},
    "mu 0.1, mid start, no maintenance": {"fixed_mu": 0.1, "maintenance": 0.0, **MID_START},
    "mu 0.1, wide start at 0.08": {"fixed_mu": 0.1, "log_std_init": -1.2},
    "mu in [0.05, 0.3] (the default), mid start": {"mu_max": 0.3, **MID_START},
    "mu decay over 20 %, mid start": {"mu_decay_fraction": 0.2, **MID_START},
    "mu decay over 20 %, no boost, mid start": {"mu_decay_fraction": 0.2, "conflict_boost": False, **MID_START},
    "mu in [0.05, 0.3], cautious start": {"mu_max": 0.3, **CAUTIOUS_START},
    "mu in [0.05, 0.3], mid start, trade-off sampling": {"mu_max": 0.3, **MID_START, **TRADE_OFF},
    "mu in [0.05, 0.3], cautious start, trade-off sampling": {"mu_max": 0.3, **CAUTIOUS_START, **TRADE_OFF},
}
"""Named departures from :data:`SHIPPED_RECIPE`, one factor (or one pair) at a time. ``mu_decay_fraction``
sets ``mu_decay_steps`` to that share of the run's steps (otherwise the whole run, as ``train/pasta.py``);
``preference`` replaces the reference preference the run starts from."""

PROBE_SAFETY_WEIGHTS = (0.1, 0.3, 0.5, 0.7, 0.9)


@dataclass(frozen=True)
class ProbeResult:
    """One training run on :class:`TradeoffEnv` and the trained policy's response to its preference."""

    variant: str
    seed: int
    steps: int
    response: PreferenceResponse
    final_mu: float
    final_attention: tuple[float, ...]
    """Mean attention of the last update's transitions, per objective."""
    wall_time: float


def probe_observations() -> np.ndarray:
    """The observations the response is read on: traffic density 0, 0.1, ..., 1 at mid-episode, previous
    gamma 0.1."""
    d = np.linspace(0.0, 1.0, 11)
    return np.stack([2.0 * d - 1.0, np.full(11, 0.5), np.full(11, 0.1), np.zeros(11)], axis=1).astype(np.float32)


def run_probe(variant: str, seed: int, steps: int, n_envs: int = 2) -> ProbeResult:
    """Train PASTA on :class:`TradeoffEnv` for ``steps`` env steps with :data:`SHIPPED_RECIPE` changed by
    ``PROBE_VARIANTS[variant]``, from the reference preference, and read its response at
    :data:`PROBE_SAFETY_WEIGHTS`."""
    import dataclasses
    import time

    from sofar_agents.pasta import PASTA, PASTAConfig
    from sofar_env.configs.objectives import REFERENCE_PREFERENCE

    if variant not in PROBE_VARIANTS:
        raise KeyError(f"unknown probe variant {variant!r}; variants: {', '.join(PROBE_VARIANTS)}")
    settings = {**SHIPPED_RECIPE, **PROBE_VARIANTS[variant]}
    fraction = settings.pop("mu_decay_fraction", 1.0)
    preference = settings.pop("preference", REFERENCE_PREFERENCE)
    settings["mu_decay_steps"] = max(1, int(round(fraction * steps)))
    config = dataclasses.replace(PASTAConfig(), **settings)
    vec_env = gym.vector.SyncVectorEnv([TradeoffEnv for _ in range(n_envs)],
                                       autoreset_mode=gym.vector.AutoresetMode.SAME_STEP)
    agent = PASTA(4, 5, [0.05], [1.0], config, preference=preference, seed=seed)
    last: dict[str, Any] = {}

    def keep(_agent: Any, stats: dict[str, Any]) -> None:
        last.update(mu=stats["mu"], attention=stats["attention"])

    start = time.perf_counter()
    agent.learn(vec_env, steps, callback=keep, log_interval=0)
    wall = time.perf_counter() - start
    vec_env.close()
    response = preference_response(agent, probe_observations(), safety_preferences(PROBE_SAFETY_WEIGHTS))
    return ProbeResult(variant, seed, agent.num_timesteps, response, float(last["mu"]),
                       tuple(float(a) for a in last["attention"]), wall)
