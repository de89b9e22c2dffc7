"""The bounded-Gaussian policy distributions of PASTA (torch).

The actor is a diagonal Gaussian over a pre-activation ``u``; a *squashing* maps ``u``
to the box action. The PPO ratio is computed on ``u`` in both cases.

- ``"sigmoid"`` (:class:`SigmoidSquash`): ``a = low + (high - low) * sigmoid(u)``, a
  bijection; the density of ``a`` subtracts ``log|da/du|``. The bounds are reached only
  in the limit ``u -> +-inf``.
- ``"clip"`` (:class:`ClipSquash`): ``a = clip(u, low, high)`` with ``u`` in action units
  (the mapping of the paper's reference, ``gamma = 0.05 + 0.95 mu`` clipped, and of
  Stable-Baselines3's Gaussian policies). The action distribution is a *censored*
  Gaussian: a point mass at each bound and the Gaussian density inside. A deterministic
  policy can sit exactly on a bound (e.g. the most conservative barrier decay) wherever
  its mean lies beyond it.
- ``"sigmoid-clip"`` (:class:`SigmoidClipSquash`): ``a = clip(low - m + (high - low + 2m)
  * sigmoid(u), low, high)`` with ``m = margin * (high - low)``: a sigmoid that reaches past
  each bound by ``m``, censored at the bounds. Between them it is the sigmoid's bijection; each
  bound holds the Gaussian mass beyond a finite ``u``, so a deterministic policy reaches a
  bound at a finite mean, and away from the bounds a sample's action is its own.
- ``"log-sigmoid"`` (:class:`LogSigmoidSquash`): ``a = low * (high / low) ** sigmoid(u)``, the
  sigmoid's bijection in ``log a`` (``low > 0``). On the gamma range [0.05, 1] the sigmoid puts
  gamma 0.07 at ``u = -3.8`` and the log-sigmoid at ``u = -2.1``: where a fixed gamma's outcome
  changes fastest (near 0.05), a unit of ``u`` moves gamma by a constant fraction of itself instead
  of a constant share of the range.
"""

from __future__ import annotations

import math

import numpy as np
import torch
import torch.nn.functional as F

from sofar_agents.pasta.config import SQUASHINGS

__all__ = ["SQUASHINGS", "ClipSquash", "LogSigmoidSquash", "SigmoidClipSquash", "SigmoidSquash", "gaussian_log_prob",
           "make_squash"]


def gaussian_log_prob(u: torch.Tensor, mean: torch.Tensor, log_std: torch.Tensor) -> torch.Tensor:
    """log N(u; mean, exp(log_std)^2), summed over the last (action) axis."""
    z = (u - mean) * torch.exp(-log_std)
    return (-0.5 * z * z - log_std - 0.5 * math.log(2.0 * math.pi)).sum(-1)


class _Bijection:
    """A squashing that is a bijection: the density of ``a`` is the Gaussian's at ``u = inverse(a)`` less
    ``log|da/du|`` (subclasses give ``inverse`` and ``log_abs_det_jacobian``)."""

    def action_log_prob(self, action: torch.Tensor, mean: torch.Tensor, log_std: torch.Tensor) -> torch.Tensor:
        """log-density of ``action`` under the squashed Gaussian N(mean, exp(log_std)^2) of ``u``."""
        u = self.inverse(action)
        return gaussian_log_prob(u, mean, log_std) - self.log_abs_det_jacobian(u)


class SigmoidSquash(_Bijection):
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

    def initial_bias(self, action: np.ndarray) -> np.ndarray:
        """The mean ``u`` whose action is ``action`` (strictly inside the bounds)."""
        frac = (action - self.low.numpy()) / self.scale.numpy()
        return np.log(frac / (1.0 - frac))


class LogSigmoidSquash(_Bijection):
    """The bijection ``a = exp(log_low + log_scale * sigmoid(u))``, ``log_scale = log(high / low)``.

    Args:
        low, high: action bounds (float32 arrays of shape ``(act_dim,)``, ``0 < low < high``), in action units.
    """

    def __init__(self, low: np.ndarray, high: np.ndarray) -> None:
        low64, high64 = np.asarray(low, np.float64), np.asarray(high, np.float64)
        if not np.all((low64 > 0.0) & (low64 < high64)):
            raise ValueError(f"the log-sigmoid squashing needs 0 < low < high, got low {low}, high {high}")
        self.log_low = torch.as_tensor(np.log(low64).astype(np.float32))
        self.log_scale = torch.as_tensor(np.log(high64 / low64).astype(np.float32))

    def __call__(self, u: torch.Tensor) -> torch.Tensor:
        """The action for pre-activation ``u``."""
        return torch.exp(self.log_low + self.log_scale * torch.sigmoid(u))

    def inverse(self, action: torch.Tensor) -> torch.Tensor:
        """The pre-activation of ``action`` (clamped 1e-6 inside the bounds)."""
        p = ((torch.log(action) - self.log_low) / self.log_scale).clamp(1e-6, 1.0 - 1e-6)
        return torch.log(p) - torch.log1p(-p)

    def log_abs_det_jacobian(self, u: torch.Tensor) -> torch.Tensor:
        """log |da/du| = log a + log log_scale + log sigmoid'(u) at ``u``, summed over the action dims."""
        return (self.log_low + self.log_scale * torch.sigmoid(u) + torch.log(self.log_scale)
                - F.softplus(-u) - F.softplus(u)).sum(-1)

    def initial_bias(self, action: np.ndarray) -> np.ndarray:
        """The mean ``u`` whose action is ``action`` (strictly inside the bounds)."""
        frac = (np.log(np.asarray(action, np.float64)) - self.log_low.numpy()) / self.log_scale.numpy()
        return np.log(frac / (1.0 - frac))


class ClipSquash:
    """``a = clip(u, low, high)``: a Gaussian in action units, censored at the bounds.

    Args:
        low, high: action bounds (float32 arrays of shape ``(act_dim,)``), in action units.
    """

    def __init__(self, low: np.ndarray, high: np.ndarray) -> None:
        self.low = torch.as_tensor(low)
        self.high = torch.as_tensor(high)

    def __call__(self, u: torch.Tensor) -> torch.Tensor:
        """The action for pre-clip ``u``."""
        return torch.minimum(torch.maximum(u, self.low), self.high)

    def log_abs_det_jacobian(self, u: torch.Tensor) -> torch.Tensor:
        """Zero: inside the bounds the map is the identity (the entropy bonus is that of ``u``)."""
        return torch.zeros(u.shape[:-1], dtype=u.dtype)

    def initial_bias(self, action: np.ndarray) -> np.ndarray:
        """The mean ``u`` whose action is ``action``: the action itself."""
        return np.asarray(action, np.float64)

    def action_log_prob(self, action: torch.Tensor, mean: torch.Tensor, log_std: torch.Tensor) -> torch.Tensor:
        """Log-likelihood of ``action`` under the censored Gaussian, summed over the action dims.

        Inside the bounds it is the Gaussian log-density; on a bound it is the log of the
        probability mass clipped onto it (``log P(u <= low)`` or ``log P(u >= high)``).
        """
        std = torch.exp(log_std)
        z = (action - mean) / std
        dens = -0.5 * z * z - log_std - 0.5 * math.log(2.0 * math.pi)
        normal = torch.distributions.Normal(torch.zeros(()), torch.ones(()))
        at_low = action <= self.low
        at_high = action >= self.high
        lo_mass = torch.log(normal.cdf((self.low - mean) / std).clamp_min(1e-30))
        hi_mass = torch.log((1.0 - normal.cdf((self.high - mean) / std)).clamp_min(1e-30))
        return torch.where(at_low, lo_mass, torch.where(at_high, hi_mass, dens)).sum(-1)


class SigmoidClipSquash:
    """``a = clip(low - m + (high - low + 2m) * sigmoid(u), low, high)``, ``m = margin * (high - low)``.

    Args:
        low, high: action bounds (float32 arrays of shape ``(act_dim,)``), in action units.
        margin: how far the sigmoid reaches beyond each bound, as a fraction of ``high - low`` (> 0).
    """

    def __init__(self, low: np.ndarray, high: np.ndarray, margin: float) -> None:
        width = np.asarray(high, np.float64) - np.asarray(low, np.float64)
        self.low, self.high = torch.as_tensor(low), torch.as_tensor(high)
        self.inner = SigmoidSquash((low - margin * width).astype(np.float32),
                                   (high + margin * width).astype(np.float32))
        self.u_low = self.inner.inverse(self.low)  # the pre-activations at which the bounds are reached
        self.u_high = self.inner.inverse(self.high)

    def __call__(self, u: torch.Tensor) -> torch.Tensor:
        """The action for pre-activation ``u``."""
        return torch.minimum(torch.maximum(self.inner(u), self.low), self.high)

    def log_abs_det_jacobian(self, u: torch.Tensor) -> torch.Tensor:
        """log |da/du| of the sigmoid at ``u`` (the entropy bonus; the clip is not counted)."""
        return self.inner.log_abs_det_jacobian(u)

    def initial_bias(self, action: np.ndarray) -> np.ndarray:
        """The mean ``u`` whose action is ``action`` (strictly inside the bounds)."""
        return self.inner.initial_bias(action)

    def action_log_prob(self, action: torch.Tensor, mean: torch.Tensor, log_std: torch.Tensor) -> torch.Tensor:
        """Log-likelihood of ``action``, summed over the action dims: the squashed density inside the
        bounds, the log of the Gaussian mass beyond ``u_low`` or ``u_high`` on a bound."""
        std = torch.exp(log_std)
        normal = torch.distributions.Normal(torch.zeros(()), torch.ones(()))
        u = self.inner.inverse(torch.minimum(torch.maximum(action, self.low), self.high))
        z = (u - mean) / std
        log_jac = torch.log(self.inner.scale) - F.softplus(-u) - F.softplus(u)
        dens = -0.5 * z * z - log_std - 0.5 * math.log(2.0 * math.pi) - log_jac  # per action dim
        lo_mass = torch.log(normal.cdf((self.u_low - mean) / std).clamp_min(1e-30))
        hi_mass = torch.log((1.0 - normal.cdf((self.u_high - mean) / std)).clamp_min(1e-30))
        return torch.where(action <= self.low, lo_mass, torch.where(action >= self.high, hi_mass, dens)).sum(-1)


def make_squash(name: str, low: np.ndarray, high: np.ndarray,
                margin: float = 0.05) -> SigmoidSquash | ClipSquash | SigmoidClipSquash | LogSigmoidSquash:
    """The squashing called ``name`` (one of :data:`SQUASHINGS`) for the box ``[low, high]`` (``margin``:
    ``"sigmoid-clip"``'s, :attr:`PASTAConfig.squash_margin`)."""
    if name == "sigmoid":
        return SigmoidSquash(low, high)
    if name == "clip":
        return ClipSquash(low, high)
    if name == "sigmoid-clip":
        return SigmoidClipSquash(low, high, margin)
    if name == "log-sigmoid":
        return LogSigmoidSquash(low, high)
    raise ValueError(f"unknown action squashing {name!r}; valid: {', '.join(SQUASHINGS)}")
