"""HPIPM's dense solver through its C API: analytic QPs, and the iteration cap that a bound of -1e9 causes."""

import numpy as np
import pytest

from sofar_env.control.refnum.hpipm import DenseQP, HPIPMOptions


def _box_qp(ns=0):
    return DenseQP(2, np.array([0, 1]), 1, np.array([2] if ns else [], dtype=int))


@pytest.mark.parametrize("lower, status, exact_iterations", [
    (-10.0, 0, None),     # an ordinary bound: converged
    (-1e6, 0, None),
    (-1e9, 1, 50),        # the reference's bound: lambda * t cannot reach the tolerance, the cap is hit
])
def test_projection_onto_a_halfplane(lower, status, exact_iterations):
    """min 1/2 |v|^2 - (1, 1) v  s.t.  lower <= v0 + v1 <= 1: v = (1/2, 1/2) whatever the lower bound."""
    v, st, it = _box_qp().solve(np.eye(2), -np.ones(2), -5 * np.ones(2), 5 * np.ones(2), np.array([[1.0, 1.0]]),
                                np.array([lower]), np.array([1.0]), np.zeros(0), np.zeros(0))
    np.testing.assert_allclose(v, [0.5, 0.5], atol=1e-6)
    assert st == status
    if exact_iterations is not None:
        assert it == exact_iterations
    else:
        assert it < 50


def test_soft_constraint_matches_its_closed_form():
    """min 1/2 (v - 3)^2 + Z s^2 / 2 + z s with v <= 1 + s: v = (3 + Z - z) / (1 + Z)."""
    qp = DenseQP(1, np.array([0]), 1, np.array([1]))
    Z, z = 1.0, 0.5
    v, st, _ = qp.solve(np.eye(1), np.array([-3.0]), np.array([-10.0]), np.array([10.0]), np.array([[1.0]]),
                        np.array([-5.0]), np.array([1.0]), np.array([Z]), np.array([z]))
    assert st == 0
    np.testing.assert_allclose(v, [(3 + Z - z) / (1 + Z)], atol=1e-7)


@pytest.mark.parametrize("bad", [
    {"mode": "fast"}, {"iter_max": 0}, {"iter_max": 2.5}, {"mu0": float("nan")}, {"tol_stat": -1.0},
    {"alpha_min": 0.0},
])
def test_options_are_validated(bad):
    with pytest.raises(ValueError):
        HPIPMOptions(**bad)
