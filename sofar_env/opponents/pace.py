"""Pace of the opponents: a pace ratio per car and the lifts of a Poisson process.

A car's arc-length speed is ``pace_i * lift_i(t) * v_profile(s)``. ``pace_i`` is
drawn per episode around the field's ratio ``rho``; ``lift_i(t)`` is 1 except
during a lift, when it ramps down to ``lift_depth`` with a raised cosine, stays
there and ramps back up, so the speed stays continuous. Lifts start at the
events of a Poisson process of rate ``lift_rate`` per car (drawn as exponential
waiting times after the end of the previous lift, so lifts never overlap).
"""

from __future__ import annotations

import math

import numpy as np

from .._jit import kernel
from .config import PaceConfig

__all__ = ["draw_paces", "lift_factor", "lift_factor_at", "LiftSchedule"]


def draw_paces(rho: float, m: int, cfg: PaceConfig, rng: np.random.Generator) -> np.ndarray:
    """Pace ratio of each of ``m`` cars: ``rho * U(1 - spread, 1 + spread)`` (``m`` draws, even if spread = 0)."""
    u = rng.uniform(1.0 - cfg.spread, 1.0 + cfg.spread, size=m)
    return rho * u if cfg.spread > 0.0 else np.full(m, float(rho))


def lift_factor(tau: float, cfg: PaceConfig) -> float:
    """Pace multiplier ``tau`` [s] after the start of a lift (1 outside the lift; :func:`lift_factor_at`)."""
    return lift_factor_at(float(tau), cfg.lift_duration, cfg.lift_ramp, cfg.lift_depth)


@kernel
def lift_factor_at(tau, duration, ramp, depth):
    """:func:`lift_factor` with the :class:`PaceConfig` fields ``lift_duration``, ``lift_ramp``, ``lift_depth``
    (inside kernels)."""
    if not (0.0 <= tau <= duration):
        return 1.0
    to_end = duration - tau
    if tau < ramp:
        w = 0.5 * (1.0 - math.cos(math.pi * tau / ramp))
    elif to_end < ramp:
        w = 0.5 * (1.0 - math.cos(math.pi * to_end / ramp))
    else:
        w = 1.0
    return 1.0 - (1.0 - depth) * w


class LiftSchedule:
    """Start times of the lifts of ``m`` cars, drawn lazily from their own generator."""

    def __init__(self, m: int, cfg: PaceConfig, rng: np.random.Generator, t0: float = 0.0):
        self.cfg = cfg
        self._rng = rng
        self.start = np.full(m, -math.inf)
        """Start of the current or last lift of each car [s]."""
        self.next = np.array([t0 + self._wait() for _ in range(m)])
        """Start of the next lift of each car [s] (inf without lifts)."""

    def _wait(self) -> float:
        rate = self.cfg.lift_rate
        return float(self._rng.exponential(1.0 / rate)) if rate > 0.0 else math.inf

    def advance(self, t_end: float) -> None:
        """Start every lift due before ``t_end`` [s] (the factor is evaluated up to then)."""
        for i in range(self.start.shape[0]):
            while self.next[i] < t_end:  # (the next lift starts after the current one has ended)
                self.start[i] = self.next[i]
                self.next[i] = self.start[i] + self.cfg.lift_duration + self._wait()

    def factor(self, i: int, t: float) -> float:
        """Pace multiplier of car ``i`` at time ``t`` [s]."""
        return lift_factor(t - float(self.start[i]), self.cfg)
