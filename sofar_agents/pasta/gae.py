"""Generalised advantage estimation with separate termination and truncation (numpy)."""

from __future__ import annotations

import numpy as np

__all__ = ["compute_gae"]


def compute_gae(
    rewards: np.ndarray,
    values: np.ndarray,
    next_values: np.ndarray,
    terminated: np.ndarray,
    truncated: np.ndarray,
    discount: float = 0.99,
    gae_lambda: float = 0.95,
) -> tuple[np.ndarray, np.ndarray]:
    """Generalised advantage estimation with termination and truncation.

    The leading axis is time (t = 0..T-1). Transition t goes from state ``s_t``
    (value ``values[t]``) with reward ``rewards[t]`` to the state ``s'_t``:

    - ``next_values[t]`` is ``V(s'_t)``, the value of the **true** successor of
      transition t: ``values[t + 1]`` inside an episode, ``V(final_obs)`` when the
      episode was truncated at t (time limit), and ``V(last_obs)`` at the end of
      the rollout. It is ignored where ``terminated[t]``.
    - ``terminated[t]``: s'_t is terminal, so nothing is bootstrapped:
      ``delta_t = r_t - V(s_t)``.
    - ``truncated[t]``: the episode was cut at t; the TD error bootstraps from
      ``V(s'_t)`` but the advantage does not flow back from step t + 1, which
      belongs to the next episode.

    Recursion (per trailing index)::

        delta_t = r_t + discount * (1 - terminated_t) * next_values_t - values_t
        A_t     = delta_t + discount * gae_lambda * (1 - done_t) * A_{t+1},
        done_t  = terminated_t or truncated_t,   A_T = 0.

    Args:
        rewards: shape ``(T, *batch)``, e.g. ``(T, n_envs, K)`` for K objectives.
        values: same shape as ``rewards``.
        next_values: same shape as ``rewards``.
        terminated: shape ``(T,)`` or a prefix of ``rewards.shape`` (e.g.
            ``(T, n_envs)``); broadcast over the remaining trailing axes.
        truncated: same shape as ``terminated``.
        discount: discount factor.
        gae_lambda: GAE lambda.

    Returns:
        ``(advantages, returns)`` with the shape of ``rewards`` (float64), where
        ``returns = advantages + values`` are the lambda-returns (critic targets).
    """
    rewards = np.asarray(rewards, dtype=np.float64)
    values = np.asarray(values, dtype=np.float64)
    next_values = np.asarray(next_values, dtype=np.float64)
    if values.shape != rewards.shape or next_values.shape != rewards.shape:
        raise ValueError(
            f"rewards {rewards.shape}, values {values.shape} and next_values "
            f"{next_values.shape} must have the same shape"
        )
    term = np.asarray(terminated, dtype=np.float64)
    trunc = np.asarray(truncated, dtype=np.float64)
    if term.shape != trunc.shape or rewards.shape[: term.ndim] != term.shape:
        raise ValueError(
            f"terminated {term.shape} and truncated {trunc.shape} must be a prefix of {rewards.shape}"
        )
    extra = (1,) * (rewards.ndim - term.ndim)
    term = term.reshape(term.shape + extra)
    done = np.maximum(term, trunc.reshape(trunc.shape + extra))

    advantages = np.zeros_like(rewards)
    last = np.zeros(rewards.shape[1:], dtype=np.float64)
    for t in reversed(range(rewards.shape[0])):
        delta = rewards[t] + discount * (1.0 - term[t]) * next_values[t] - values[t]
        last = delta + discount * gae_lambda * (1.0 - done[t]) * last
        advantages[t] = last
    return advantages, advantages + values
