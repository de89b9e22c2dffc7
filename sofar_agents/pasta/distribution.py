"""The squashed Gaussian policy distribution of PASTA (torch).

The actor is a diagonal Gaussian over a pre-activation ``u``; the action is
``a = low + (high - low) * sigmoid(u)``. The PPO ratio is computed on ``u`` (the
change-of-variables term cancels in the ratio); the density of ``a`` subtracts
``log|da/du|`` (:meth:`SigmoidSquash.log_abs_det_jacobian`).
"""

from __future__ import annotations

import math

import numpy as np
import torch
import torch.nn.functional as F

__all__ = ["gaussian_log_prob", "SigmoidSquash"]


def gaussian_log_prob(u: torch.Tensor, mean: torch.Tensor, log_std: torch.Tensor) -> torch.Tensor:
    """log N(u; mean, exp(log_std)^2), summed over the last (action) axis."""
    z = (u - mean) * torch.exp(-log_std)
    return (-0.5 * z * z - log_std - 0.5 * math.log(2.0 * math.pi)).sum(-1)


class SigmoidSquash:
    """The bijection ``a = low + scale * sigmoid(u)`` between ``u`` and a box action.

    Args:
        low, high: action bounds (float32 arrays of shape ``(act_dim,)``), in action units.
    """

    def __init__(self, low: np.ndarray, high: np.ndarray) -> None:
        self.low = torch.as_tensor(low)
        self.scale = torch.as_tensor(high - low)

    def __call__(self, u: torch.Tensor) -> torch.Tensor:
        """The action for pre-activation ``u``."""
        return self.low + self.scale * torch.sigmoid(u)

    def inverse(self, action: torch.Tensor) -> torch.Tensor:
        """The pre-activation of ``action`` (clamped 1e-6 inside the bounds)."""
        p = ((action - self.low) / self.scale).clamp(1e-6, 1.0 - 1e-6)
        return torch.log(p) - torch.log1p(-p)

    def log_abs_det_jacobian(self, u: torch.Tensor) -> torch.Tensor:
        """log |da/du| at ``u``, summed over the action dims."""
        return (torch.log(self.scale) - F.softplus(-u) - F.softplus(u)).sum(-1)
