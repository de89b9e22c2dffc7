"""The rollout buffer: the arrays of one PASTA rollout, as consumed by the update."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["RolloutBuffer"]


@dataclass
class RolloutBuffer:
    """One rollout of ``T`` steps from ``N`` environments (arrays are ``(T, N, ...)``).

    Rewards are stored raw (environment units); values are the critic's outputs in
    normalised units at collection time.
    """

    obs: np.ndarray
    """Observations, ``(T, N, obs_dim)`` float32."""
    preferences: np.ndarray
    """Preference of the episode each step belongs to, ``(T, N, K)`` float32."""
    pre_actions: np.ndarray
    """Pre-squash Gaussian samples u, ``(T, N, act_dim)`` float32."""
    actions: np.ndarray
    """Actions sent to the environment, ``(T, N, act_dim)`` float32."""
    log_probs: np.ndarray
    """log N(u; mean, std) at collection, ``(T, N)`` float32."""
    rewards: np.ndarray
    """Raw reward vectors, ``(T, N, K)`` float64."""
    values: np.ndarray
    """V(s_t) per objective, ``(T, N, K)`` float64 (normalised units)."""
    next_values: np.ndarray
    """V of the true successor of each transition (see :func:`compute_gae`)."""
    terminated: np.ndarray
    """``(T, N)`` bool."""
    truncated: np.ndarray
    """``(T, N)`` bool."""
    episodes: list[dict[str, Any]]
    """Episodes that ended during the rollout: ``returns`` (K raw), ``length`` and
    the final-info entries ``is_success``, ``overtakes``, ``laps``, ``collision``,
    ``off_track`` when present."""
