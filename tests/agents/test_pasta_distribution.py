"""The squashed Gaussian: sigmoid squash, its inverse and log-Jacobian, Gaussian log-density."""

from __future__ import annotations

import math

import numpy as np
import torch

from sofar_agents.pasta.distribution import SigmoidSquash, gaussian_log_prob


def test_squash_maps_onto_the_bounds_and_inverts() -> None:
    sq = SigmoidSquash(np.array([0.05], np.float32), np.array([1.0], np.float32))
    u = torch.linspace(-5, 5, 11).reshape(-1, 1)
    a = sq(u)
    assert torch.all((a > 0.05) & (a < 1.0))
    torch.testing.assert_close(sq(torch.zeros(1, 1)), torch.tensor([[0.525]]))
    torch.testing.assert_close(sq.inverse(a), u, atol=1e-4, rtol=0)
    assert torch.isfinite(sq.inverse(torch.tensor([[0.05], [1.0]]))).all()  # clamped at the bounds


def test_log_abs_det_jacobian_matches_autograd() -> None:
    sq = SigmoidSquash(np.array([0.05, -1.0]), np.array([1.0, 3.0]))  # float64
    u = torch.tensor([[0.3, -2.0]], dtype=torch.float64)
    jac = torch.autograd.functional.jacobian(sq, u).reshape(2, 2)
    expected = torch.log(torch.diagonal(jac).abs()).sum()
    torch.testing.assert_close(sq.log_abs_det_jacobian(u)[0], expected)


def test_gaussian_log_prob() -> None:
    u, mean, log_std = torch.tensor([[1.0, -1.0]]), torch.tensor([[0.0, 0.0]]), torch.tensor([0.0, math.log(2.0)])
    expected = (-0.5 - 0.5 * math.log(2 * math.pi)) + (-0.125 - math.log(2.0) - 0.5 * math.log(2 * math.pi))
    torch.testing.assert_close(gaussian_log_prob(u, mean, log_std), torch.tensor([expected]))
