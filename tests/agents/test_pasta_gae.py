"""GAE against hand computations: termination, truncation, lambda limits, broadcasting."""

from __future__ import annotations

import numpy as np
import pytest

from sofar_agents import compute_gae

# One env, five transitions: terminated at t = 1, truncated (time limit) at t = 3.
REWARDS = np.array([1.0, 2.0, 3.0, 4.0, 5.0])
VALUES = np.array([0.5, 0.6, 0.7, 0.8, 0.9])
# V of the true successor of each transition: V(s_1), ignored (terminal), V(s_3),
# V(final_obs) of the truncated episode, V(last_obs) after the rollout.
NEXT_VALUES = np.array([0.6, 99.0, 0.8, 10.0, 2.0])
TERMINATED = np.array([False, True, False, False, False])
TRUNCATED = np.array([False, False, False, True, False])
DISCOUNT, LAMBDA = 0.9, 0.8


def test_gae_matches_hand_computation() -> None:
    adv, ret = compute_gae(REWARDS, VALUES, NEXT_VALUES, TERMINATED, TRUNCATED, DISCOUNT, LAMBDA)
    a4 = 5.0 + 0.9 * 2.0 - 0.9  # bootstrap from the last observation
    a3 = 4.0 + 0.9 * 10.0 - 0.8  # truncated: bootstrap from V(final_obs), no flow from t = 4
    a2 = (3.0 + 0.9 * 0.8 - 0.7) + 0.9 * 0.8 * a3
    a1 = 2.0 - 0.6  # terminated: no bootstrap
    a0 = (1.0 + 0.9 * 0.6 - 0.5) + 0.9 * 0.8 * a1
    expected = np.array([a0, a1, a2, a3, a4])
    np.testing.assert_allclose(adv, expected, rtol=1e-12)
    np.testing.assert_allclose(ret, expected + VALUES, rtol=1e-12)
    assert expected[3] == pytest.approx(12.2) and expected[2] == pytest.approx(11.804)


def test_gae_lambda_limits() -> None:
    # lambda = 0: one-step TD errors.
    adv0, _ = compute_gae(REWARDS, VALUES, NEXT_VALUES, TERMINATED, TRUNCATED, DISCOUNT, 0.0)
    td = REWARDS + DISCOUNT * (1 - TERMINATED) * NEXT_VALUES - VALUES
    np.testing.assert_allclose(adv0, td)
    # lambda = 1: discounted returns to the episode end (+ bootstrap on truncation) minus V.
    _, ret1 = compute_gae(REWARDS, VALUES, NEXT_VALUES, TERMINATED, TRUNCATED, DISCOUNT, 1.0)
    mc = np.array([1 + 0.9 * 2, 2, 3 + 0.9 * (4 + 0.9 * 10), 4 + 0.9 * 10, 5 + 0.9 * 2])
    np.testing.assert_allclose(ret1, mc)


def test_gae_broadcasts_over_envs_and_objectives() -> None:
    k = 3
    scale = np.array([1.0, -2.0, 0.5])
    rewards = REWARDS[:, None, None] * scale  # (T, 1 env, K)
    values = VALUES[:, None, None] * scale
    next_values = NEXT_VALUES[:, None, None] * scale
    adv, _ = compute_gae(rewards, values, next_values, TERMINATED[:, None], TRUNCATED[:, None], DISCOUNT, LAMBDA)
    ref, _ = compute_gae(REWARDS, VALUES, NEXT_VALUES, TERMINATED, TRUNCATED, DISCOUNT, LAMBDA)
    assert adv.shape == (5, 1, k)
    np.testing.assert_allclose(adv[:, 0, :], ref[:, None] * scale)
    with pytest.raises(ValueError):
        compute_gae(rewards, values[:-1], next_values, TERMINATED, TRUNCATED)
