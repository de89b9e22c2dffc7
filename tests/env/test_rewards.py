"""The reward terms and the safety cost: analytic values of hand-built steps."""

import math

import numpy as np
import pytest

from sofar_env.config import OBJECTIVE_NAMES, RewardWeights
from sofar_env.rewards import (barrier_margin_term, gamma_smoothness_term, overtake_term, progress_term,
                               reward_vector, safety_cost, safety_term, scalarize)


@pytest.mark.parametrize("collision, off_track, expected", [
    (False, False, 0.0), (True, False, -1.0), (False, True, -1.0), (True, True, -1.0)])
def test_safety_term(collision, off_track, expected):
    assert safety_term(collision, off_track) == expected


def test_overtake_term_counts():
    assert overtake_term(0) == 0.0 and overtake_term(2) == 2.0


def test_progress_term_is_one_at_the_profile_speed():
    # 6 m in 0.1 s where the profile says 60 m/s: exactly the profile's progress
    assert progress_term(6.0, 60.0, 0.1) == pytest.approx(1.0)
    assert progress_term(4.8, 60.0, 0.1) == pytest.approx(0.8)
    assert progress_term(-1.0, 50.0, 0.1) == pytest.approx(-0.2)  # going backwards
    # a standing profile (pit, start) is floored at 1 m/s, no division by zero
    assert progress_term(0.05, 0.0, 0.1) == pytest.approx(0.5)


@pytest.mark.parametrize("slack, min_h, expected", [
    (0.0, 2.0, 0.0),          # free, outside every ellipse
    (0.0, math.inf, 0.0),     # no opponent
    (0.25, 0.5, -0.25),       # slack only
    (0.0, -0.3, -0.3),        # inside an ellipse by 0.3
    (0.5, -0.4, -0.9),        # both add up
    (2.0, -0.5, -1.0),        # saturated at -1
    (-1e-9, 1.0, 0.0),        # solver noise below zero is no reward
])
def test_barrier_margin_term(slack, min_h, expected):
    assert barrier_margin_term(slack, min_h) == pytest.approx(expected)


def test_gamma_smoothness_term():
    assert gamma_smoothness_term(0.3, 0.5) == pytest.approx(-0.2)
    assert gamma_smoothness_term(0.5, 0.5) == 0.0
    assert gamma_smoothness_term(1.0, 0.05) == pytest.approx(-0.95)


def test_reward_vector_order_matches_objective_names():
    v = reward_vector(collision=True, off_track=False, overtakes=1, progress=3.0, profile_speed=30.0, dt=0.1,
                      barrier_slack=0.1, min_h=-0.2, gamma=0.7, previous_gamma=0.5)
    assert v.shape == (len(OBJECTIVE_NAMES),)
    expected = dict(safety=-1.0, overtakes=1.0, progress=1.0, barrier_margin=-0.3, gamma_smoothness=-0.2)
    np.testing.assert_allclose(v, [expected[k] for k in OBJECTIVE_NAMES])


def test_scalarize_is_the_weighted_sum_with_the_default_weights():
    w = RewardWeights().as_array()
    v = np.array([-1.0, 2.0, 0.8, -0.5, -0.1])
    assert scalarize(v, w) == pytest.approx(-10.0 + 2.0 + 0.05 * 0.8 - 0.5 * 0.5 - 0.1 * 0.1)
    assert isinstance(scalarize(v, w), float)


def test_safety_cost():
    assert safety_cost(False, False, 0.0) == 0.0
    assert safety_cost(True, True, 0.25) == pytest.approx(2.25)
    assert safety_cost(False, False, -0.1) == 0.0
