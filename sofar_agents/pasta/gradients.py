"""Per-objective actor gradients: extraction, conflict measurement and PCGrad (torch)."""

from __future__ import annotations

import numpy as np
import torch

__all__ = ["objective_gradients", "add_flat_gradient", "gradient_conflict_ratio", "pcgrad_project"]


def objective_gradients(per_objective_loss: torch.Tensor, params: list[torch.nn.Parameter]) -> torch.Tensor:
    """Gradient of each of the K losses w.r.t. ``params``, flattened: shape ``(K, P)``.

    The graph is retained (a further backward pass through it is allowed) and the
    parameters' ``.grad`` are left untouched; a parameter a loss does not depend on
    contributes zeros.
    """
    grads = []
    for j in range(per_objective_loss.shape[0]):
        gj = torch.autograd.grad(per_objective_loss[j], params, retain_graph=True, allow_unused=True)
        grads.append(torch.cat([(g if g is not None else torch.zeros_like(p)).reshape(-1)
                                for g, p in zip(gj, params)]))
    return torch.stack(grads)


def add_flat_gradient(params: list[torch.nn.Parameter], flat: torch.Tensor) -> None:
    """Add the flattened gradient ``flat`` (layout of :func:`objective_gradients`) to ``p.grad``."""
    offset = 0
    for p in params:
        n_el = p.numel()
        g = flat[offset:offset + n_el].view_as(p)
        p.grad = g.clone() if p.grad is None else p.grad + g
        offset += n_el


def gradient_conflict_ratio(grads: torch.Tensor, eps: float = 1e-12) -> float:
    """Fraction of objective pairs whose gradients have a negative cosine.

    ``grads`` has shape ``(K, P)``. Objectives with a zero gradient (no signal) are
    left out; with fewer than two remaining objectives the ratio is 0.
    """
    norms = grads.norm(dim=1)
    g = grads[norms > eps]
    n = g.shape[0]
    if n < 2:
        return 0.0
    dots = g @ g.T
    iu = torch.triu_indices(n, n, offset=1)
    return float((dots[iu[0], iu[1]] < 0).float().mean())


def pcgrad_project(grads: torch.Tensor, rng: np.random.Generator) -> torch.Tensor:
    """PCGrad (Yu et al., 2020): de-conflict per-objective gradients.

    Each ``g_i`` is projected, in a random order, against every **other** original
    gradient ``g_j`` with which it conflicts: ``g_i <- g_i - (g_i . g_j)/|g_j|^2 g_j``
    when ``g_i . g_j < 0``. Returns the projected gradients, shape ``(K, P)``.
    """
    k = grads.shape[0]
    out = grads.clone()
    sq = (grads * grads).sum(dim=1)
    for i in range(k):
        g = grads[i].clone()
        for j in rng.permutation(k):
            if j == i or sq[j] <= 0:
                continue
            dot = torch.dot(g, grads[j])
            if dot < 0:
                g = g - dot / sq[j] * grads[j]
        out[i] = g
    return out
