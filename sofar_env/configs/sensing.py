"""Configuration of the sensor model of the opponents (:class:`SensorConfig`; the model is
:mod:`sofar_env.sensing`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..domains import check_fields, flag, integer, real

__all__ = ["SensorConfig"]


@dataclass(frozen=True)
class SensorConfig:
    """Sensor model of the opponents (off by default: perfect sensing)."""

    enabled: bool = flag(False)
    """Apply the model; otherwise the true rows are returned unchanged and no random number is drawn."""
    sigma_s: float = real(1.0, ge=0.0, unit="m")
    """Standard deviation of the arc-length error [m], >= 0."""
    sigma_n: float = real(0.3, ge=0.0, unit="m")
    """Standard deviation of the lateral-offset error [m], >= 0."""
    sigma_v: float = real(0.5, ge=0.0, unit="m/s")
    """Standard deviation of the speed error [m/s], >= 0."""
    correlation_time: float = real(0.3, gt=0.0, unit="s")
    """Correlation time tau of the Gauss-Markov errors [s], > 0."""
    latency_steps: int = integer(2, ge=0)
    """Delay of the output in control steps [-], >= 0."""
    tracker_alpha: float = real(0.3, gt=0.0, le=1.0)
    """Position gain of the alpha-beta tracker of the lateral offset [-], in (0, 1]. Decision:
    ``docs/decisions/lateral-prediction.md``."""
    tracker_beta: float = real(0.05, gt=0.0, lt=2.0)
    """Rate gain of the alpha-beta tracker [-], in (0, 2); higher gains react faster and are noisier.
    Decision: ``docs/decisions/lateral-prediction.md``."""
    jump_distance: float = real(50.0, gt=0.0, unit="m")
    """A true arc-length change above this between two calls restarts the identity's track [m], > 0."""
    latency_compensation: bool = flag(True)
    """Carry the delayed measurement forward over its age at the measured speed and lateral rate
    (``s + v * age``, ``n + n_dot * age``); off, the output is the raw delayed measurement."""

    def __post_init__(self) -> None:
        check_fields(self, "race.sensor")

    @property
    def sigmas(self) -> np.ndarray:
        return np.array([self.sigma_s, self.sigma_n, self.sigma_v])
