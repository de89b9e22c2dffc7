"""The PPO epochs of a PASTA update on a fixed, flattened rollout (torch).

Per minibatch the actor loss is the attention-weighted sum of the per-objective
clipped surrogates, ``L = -sum_j mean_b alpha_bj * min(r_b A_bj, clip(r_b) A_bj)``,
minus the entropy bonus; the critic loss is the squared error of every value head.
The per-objective actor gradients are taken apart to measure their conflict (and,
with ``config.pcgrad``, to de-conflict them) before they are summed.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
from torch import nn

from sofar_agents.pasta.config import PASTAConfig
from sofar_agents.pasta.distribution import ClipSquash, SigmoidSquash, gaussian_log_prob
from sofar_agents.pasta.gradients import (
    add_flat_gradient,
    gradient_conflict_ratio,
    objective_gradients,
    pcgrad_project,
)

__all__ = ["UpdateBatch", "ppo_epochs"]

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class UpdateBatch:
    """The B transitions of one update, flattened over time and environments."""

    inputs: torch.Tensor
    """Network inputs ``[obs, w]``, ``(B, obs_dim + K)`` float32."""
    pre_actions: torch.Tensor
    """Pre-squash actions u taken, ``(B, act_dim)``."""
    log_probs: torch.Tensor
    """log N(u) under the policy that collected the rollout, ``(B,)``."""
    advantages: torch.Tensor
    """Per-objective GAE advantages, ``(B, K)`` float32 (normalised reward units)."""
    returns: torch.Tensor
    """Per-objective lambda-returns (critic targets), ``(B, K)`` float32."""
    attention: torch.Tensor
    """Attention weights alpha of each transition, ``(B, K)`` float32."""


def ppo_epochs(
    actor: nn.Module,
    critic: nn.Module,
    optimizer: torch.optim.Optimizer,
    squash: SigmoidSquash | ClipSquash,
    batch: UpdateBatch,
    config: PASTAConfig,
    rng: np.random.Generator,
    torch_gen: torch.Generator,
) -> tuple[dict[str, list[float]], int, int]:
    """Run ``config.n_epochs`` passes of minibatch PPO over ``batch``.

    ``rng`` shuffles the minibatches (and orders PCGrad's projections); ``torch_gen``
    draws the reparameterised samples of the entropy estimate. Stops early when a
    minibatch's approximate KL exceeds ``1.5 * config.target_kl``.

    Returns ``(log, n_minibatches, epochs_completed)``; ``log`` maps
    ``policy_loss``, ``value_loss``, ``entropy``, ``approx_kl``, ``clipfrac`` to one
    value per minibatch and ``conflict`` to one per measured minibatch.
    """
    cfg = config
    b = batch.inputs.shape[0]
    actor_params = [p for p in actor.parameters()]
    critic_params = [p for p in critic.parameters()]
    log: dict[str, list[Any]] = {"policy_loss": [], "value_loss": [], "entropy": [], "approx_kl": [],
                                 "clipfrac": [], "conflict": []}
    continue_training = True
    n_mb = 0
    epochs_done = 0
    for _epoch in range(cfg.n_epochs):
        perm = rng.permutation(b)
        for start in range(0, b, cfg.batch_size):
            idx = torch.as_tensor(perm[start:start + cfg.batch_size])
            x, u, old_logp = batch.inputs[idx], batch.pre_actions[idx], batch.log_probs[idx]
            a_mb, r_mb, al_mb = batch.advantages[idx], batch.returns[idx], batch.attention[idx]

            mean = actor(x)
            log_std = actor.log_std
            new_logp = gaussian_log_prob(u, mean, log_std)
            logratio = new_logp - old_logp
            ratio = torch.exp(logratio)
            with torch.no_grad():
                approx_kl = float(((ratio - 1.0) - logratio).mean())
                clipfrac = float(((ratio - 1.0).abs() > cfg.clip_range).float().mean())
            if cfg.target_kl is not None and approx_kl > 1.5 * cfg.target_kl:
                continue_training = False
                logger.debug("early stop at epoch %d: approx_kl %.4f", _epoch, approx_kl)
                break

            if cfg.normalize_advantage and a_mb.shape[0] > 1:
                a_mb = a_mb - a_mb.mean(dim=0)
                a_mb = a_mb / (a_mb.var(dim=0).mean().sqrt() + 1e-8)
            r = ratio.unsqueeze(-1)
            surr = torch.min(r * a_mb, torch.clamp(r, 1.0 - cfg.clip_range, 1.0 + cfg.clip_range) * a_mb)
            per_obj_loss = -(al_mb * surr).mean(dim=0)  # (K,)

            eps = torch.randn(mean.shape, generator=torch_gen)
            u_rep = mean + torch.exp(log_std) * eps
            gauss_ent = (0.5 + 0.5 * math.log(2.0 * math.pi) + log_std).sum()
            entropy = gauss_ent + squash.log_abs_det_jacobian(u_rep).mean()

            optimizer.zero_grad(set_to_none=True)
            measure = cfg.pcgrad or n_mb % cfg.conflict_every == 0
            if measure:
                g_mat = objective_gradients(per_obj_loss, actor_params)
                log["conflict"].append(gradient_conflict_ratio(g_mat))
                if cfg.pcgrad:
                    g_mat = pcgrad_project(g_mat, rng)
                (-cfg.ent_coef * entropy).backward()
                add_flat_gradient(actor_params, g_mat.sum(dim=0))
            else:
                (per_obj_loss.sum() - cfg.ent_coef * entropy).backward()

            values = critic(x)
            value_loss = 0.5 * ((values - r_mb) ** 2).sum(dim=-1).mean()
            (cfg.vf_coef * value_loss).backward()
            nn.utils.clip_grad_norm_(actor_params, cfg.max_grad_norm)
            nn.utils.clip_grad_norm_(critic_params, cfg.max_grad_norm)
            optimizer.step()
            n_mb += 1

            log["policy_loss"].append(float(per_obj_loss.detach().sum()))
            log["value_loss"].append(float(value_loss.detach()))
            log["entropy"].append(float(entropy.detach()))
            log["approx_kl"].append(approx_kl)
            log["clipfrac"].append(clipfrac)
        if not continue_training:
            break
        epochs_done += 1
    return log, n_mb, epochs_done
