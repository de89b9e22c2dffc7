"""Smooth-Tchebycheff attention over the objectives (numpy).

Each objective j has a *regret*: the shortfall of its current performance from a
running *utopia* (an estimate of the best achievable return), in units of the
objective's return scale, plus a small margin. The attention weights

``alpha = (1 - maintenance) * softmax(w * regret / mu) + maintenance / K``

weight the per-objective policy losses. The smoothing temperature mu is set by
:class:`MuController`: it decays over training and is pushed back up when the
per-objective gradients conflict.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from sofar_agents.pasta.config import PASTAConfig

__all__ = ["attention_weights", "update_utopia", "normalised_regret", "MuController"]


def update_utopia(utopia: np.ndarray | None, best: np.ndarray, decay: float) -> np.ndarray:
    """Running utopia after a rollout whose estimate of the best achievable returns is ``best``.

    The first estimate is taken as is. Afterwards the utopia is the running maximum of
    the estimates, relaxing at rate ``decay`` towards an estimate below it:
    ``max(best, utopia - decay * (utopia - best))``. Raw return units.
    """
    if utopia is None:
        return best.copy()
    relaxed = utopia - decay * (utopia - best)
    return np.maximum(best, relaxed)


def normalised_regret(
    perf: np.ndarray, utopia: np.ndarray, scale: np.ndarray, margin: float, clip: float
) -> np.ndarray:
    """Normalised regret ``min(max(utopia - perf, 0) / scale + margin, clip)`` per objective.

    ``perf`` and ``utopia`` are in raw return units, ``scale`` is the return scale of
    each objective; ``margin`` and ``clip`` are in units of that scale.
    """
    regret = np.maximum(utopia - perf, 0.0) / scale + margin
    return np.minimum(regret, clip)


def attention_weights(
    regret: np.ndarray, preference: np.ndarray, mu: float, maintenance: float
) -> np.ndarray:
    """Smooth-Tchebycheff attention over K objectives.

    ``alpha = (1 - maintenance) * softmax(w * regret / mu) + maintenance / K``,
    softmax over the last axis. As ``mu -> inf`` alpha becomes uniform; as
    ``mu -> 0`` it becomes one-hot on the largest weighted regret ``w_j regret_j``
    (mixed with the uniform floor ``maintenance / K``). Broadcasts over leading axes.
    """
    if mu <= 0:
        raise ValueError(f"mu must be positive, got {mu}")
    z = np.asarray(preference, dtype=np.float64) * np.asarray(regret, dtype=np.float64) / mu
    z = z - z.max(axis=-1, keepdims=True)
    e = np.exp(z)
    soft = e / e.sum(axis=-1, keepdims=True)
    k = soft.shape[-1]
    return (1.0 - maintenance) * soft + maintenance / k


@dataclass
class MuController:
    """Adaptive smoothing temperature of the Tchebycheff attention.

    Target at env step ``t`` with last measured conflict ratio ``c``::

        target = mu_max - (mu_max - mu_min) * min(t / decay_steps, 1)    (if decay)
        target += (mu_max - target) * (c - kappa) / (1 - kappa)          (if boost and c > kappa)
        mu     <- clip((1 - ema) * mu + ema * target, mu_min, mu_max)
    """

    mu_max: float = 0.3
    mu_min: float = 0.05
    ema: float = 0.05
    kappa: float = 0.4
    decay_steps: int = 1_000_000
    decay: bool = True
    conflict_boost: bool = True
    mu: float = field(default=float("nan"))

    def __post_init__(self) -> None:
        if math.isnan(self.mu):
            self.mu = self.mu_max

    @classmethod
    def from_config(cls, config: PASTAConfig) -> MuController:
        return cls(
            mu_max=config.mu_max,
            mu_min=config.mu_min,
            ema=config.mu_ema,
            kappa=config.kappa,
            decay_steps=config.mu_decay_steps,
            decay=config.mu_decay,
            conflict_boost=config.conflict_boost,
        )

    def target(self, step: int, conflict: float) -> float:
        """Target mu for env step ``step`` and conflict ratio ``conflict``."""
        frac = min(max(step, 0) / max(self.decay_steps, 1), 1.0) if self.decay else 0.0
        target = self.mu_max - (self.mu_max - self.mu_min) * frac
        if self.conflict_boost and conflict > self.kappa:
            target += (self.mu_max - target) * (conflict - self.kappa) / (1.0 - self.kappa)
        return target

    def update(self, step: int, conflict: float) -> float:
        """Move mu one EMA step towards its target and return it."""
        mu = (1.0 - self.ema) * self.mu + self.ema * self.target(step, conflict)
        self.mu = float(min(max(mu, self.mu_min), self.mu_max))
        return self.mu
