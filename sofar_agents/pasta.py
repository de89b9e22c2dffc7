"""PASTA: multi-objective PPO with adaptive smooth-Tchebycheff attention.

PASTA (Policy optimisation via Adaptive Smooth Tchebycheff Attention) learns the
barrier decay gamma of the MPC-DCBF from a vector of K named objectives. It is
PPO with three additions:

1. **Per-objective critics and advantages.** A branched critic (shared trunk, one
   value head per objective) is fitted to per-objective returns expressed in units
   of a running scale of that objective's discounted return (``RunningMeanStd``),
   so that all heads see targets of comparable size. Advantages are computed per
   objective with GAE (:func:`compute_gae`), bootstrapping from ``V(final_obs)``
   on truncation and from zero on termination.
2. **Smooth-Tchebycheff attention on the policy update.** Each objective j has a
   *regret*: the shortfall of its current performance (the rollout's mean
   lambda-return) from a running utopia, in units of the return scale, plus a small
   margin. The utopia estimates the best achievable return: each rollout proposes
   the 90th percentile (``utopia_quantile``) of its per-state lambda-returns, and the
   utopia is the running maximum of these proposals, relaxing slowly
   (``utopia_decay``) towards lower ones. The attention weights

   ``alpha = (1 - maintenance) * softmax(w * regret / mu) + maintenance / K``

   weight the per-objective clipped surrogates in the **actor** loss
   ``L = -sum_j mean_b alpha_bj * min(r_b A_bj, clip(r_b) A_bj)``. With a large
   smoothing temperature mu this is a uniform linear scalarisation; as mu -> 0 it
   becomes a Tchebycheff (max-regret) scalarisation, which can reach points in
   non-convex dents of a Pareto front that no linear scalarisation selects.
3. **Adaptive smoothing.** mu decays linearly from ``mu_max`` to ``mu_min`` over
   ``mu_decay_steps`` environment steps, is pushed back towards ``mu_max`` when the
   per-objective actor gradients conflict (fraction of objective pairs with a
   negative cosine above ``kappa``), and follows that target through an EMA.
   Optionally the per-objective gradients are de-conflicted with PCGrad.

Action squashing: the actor is a Gaussian over a pre-activation ``u``; the action
is ``a = low + (high - low) * sigmoid(u)``. The PPO ratio is computed on ``u``
(the change-of-variables term cancels in the ratio); :meth:`PASTA.log_prob`
returns the log-density of ``a`` including ``-log|da/du|``. The deterministic
action is the squashed mean (the median of the squashed distribution). The
entropy bonus is the entropy of the squashed distribution, estimated with one
reparameterised sample per state.

Rollouts are collected from a Gymnasium vector environment created with
``autoreset_mode=AutoresetMode.SAME_STEP`` (the final observation of an episode
is then in ``info["final_obs"]``). Reward vectors are taken from the environment
reward when it has shape ``(n_envs, K)``, otherwise from ``info["reward_vector"]``
(see :class:`sofar_agents.wrappers.LinearReward`).

Randomness: one ``numpy.random.Generator`` and one ``torch.Generator`` owned by the
agent, both derived from ``seed``. The global RNGs are never touched.
"""

from __future__ import annotations

import ast
import copy
import dataclasses
import inspect
import json
import logging
import math
import time
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from sofar_agents.policies import (
    FORMAT_VERSION,
    checkpoint_paths,
    read_checkpoint_metadata,
    validate_actor_state,
)

__all__ = [
    "PASTA",
    "PASTAConfig",
    "RolloutBuffer",
    "RunningMeanStd",
    "MuController",
    "compute_gae",
    "attention_weights",
    "gradient_conflict_ratio",
    "pcgrad_project",
    "dataclass_field_docs",
]

logger = logging.getLogger(__name__)


# --------------------------------------------------------------------------- config


@dataclass(frozen=True)
class PASTAConfig:
    """Hyper-parameters of PASTA. Defaults follow the reference implementation
    (REFERENCE_FACTS.md 7.7) and the paper (2 x 256 hidden units)."""

    learning_rate: float = 3e-4
    """Adam learning rate shared by the actor and the critic."""
    adam_eps: float = 1e-5
    """Adam epsilon."""
    n_steps: int = 2048
    """Environment steps collected **per environment** per rollout; one update
    consumes ``n_steps * n_envs`` transitions."""
    batch_size: int = 64
    """Minibatch size (transitions) for the PPO epochs."""
    n_epochs: int = 10
    """Passes over the rollout per update."""
    clip_range: float = 0.2
    """PPO clipping parameter epsilon of the probability ratio."""
    discount: float = 0.99
    """Discount factor of the returns (the RL gamma, not the barrier gamma)."""
    gae_lambda: float = 0.95
    """GAE lambda."""
    vf_coef: float = 0.5
    """Weight c1 of the value loss (sum over the heads of squared errors of the
    normalised per-objective returns)."""
    ent_coef: float = 0.01
    """Weight c2 of the entropy bonus (entropy of the squashed action distribution)."""
    max_grad_norm: float = 0.5
    """Global gradient-norm clip, applied separately to the actor and the critic."""
    target_kl: float | None = None
    """If set, stop the epochs of an update early once the approximate KL of a
    minibatch exceeds ``1.5 * target_kl``."""
    normalize_advantage: bool = True
    """Centre each objective's advantages per minibatch and divide all of them by
    one common scale (root-mean of the per-objective variances). A common scale
    keeps the relative size of the objectives: an objective without signal is not
    blown up into unit-variance noise."""
    normalize_returns: bool = True
    """Divide each objective's rewards by a running standard deviation of its
    discounted return (Welford / Chan parallel update over all transitions seen)."""
    reward_clip: float | None = 10.0
    """Clip of the normalised rewards (in return standard deviations); None disables."""
    scalarization: str = "stch"
    """``"stch"``: smooth-Tchebycheff attention weights; ``"linear"``: the
    preference itself (alpha = w), i.e. linear scalarisation, for ablations."""
    maintenance: float = 0.15
    """Maintenance rate: share of the attention mixed uniformly over the objectives,
    so that no objective's weight drops below ``maintenance / K``."""
    utopia_margin: float = 0.1
    """Margin added to every regret (in return standard deviations), i.e. the utopia
    lies slightly beyond the best performance seen. It lets the preference w shape
    the attention even when every objective is at its utopia."""
    utopia_quantile: float = 0.9
    """Quantile of the rollout's per-state lambda-returns (per objective) taken as that
    rollout's estimate of the best achievable return. The running utopia is the
    (slowly decaying) maximum of these estimates; 0.5 to 1."""
    utopia_decay: float = 0.01
    """Per-update rate at which the running utopia relaxes towards the current
    estimate when the latter is below it (0 = plain running maximum)."""
    regret_clip: float = 10.0
    """Upper clip of the normalised regret (return standard deviations)."""
    mu_max: float = 10.0
    """Upper bound and initial value of the smoothing temperature mu."""
    mu_min: float = 0.05
    """Lower bound of mu, reached at the end of the linear decay."""
    mu_ema: float = 0.05
    """EMA rate with which mu follows its target each update."""
    kappa: float = 0.4
    """Conflict threshold: above this gradient-conflict ratio the target mu is pushed
    back towards ``mu_max`` in proportion to ``(conflict - kappa) / (1 - kappa)``."""
    mu_decay_steps: int = 1_000_000
    """Environment steps over which the target mu decays linearly from ``mu_max``
    to ``mu_min`` (the reference's ``total_train_steps``)."""
    mu_decay: bool = True
    """Enable the linear decay of the target mu."""
    conflict_boost: bool = True
    """Enable the conflict-driven push of the target mu towards ``mu_max``."""
    fixed_mu: float | None = None
    """If set, use this constant mu and disable the controller."""
    pcgrad: bool = False
    """De-conflict the per-objective actor gradients with PCGrad before summing."""
    conflict_every: int = 1
    """Measure the gradient conflict on every n-th minibatch (PCGrad, when on, needs
    the per-objective gradients of every minibatch regardless)."""
    hidden_sizes: tuple[int, ...] = (256, 256)
    """Hidden widths of the actor and of the critic trunk (tanh activations)."""
    critic_head_hidden: int = 64
    """Hidden width of each per-objective value head (0 = a single linear layer)."""
    log_std_init: float = -0.5
    """Initial log standard deviation of the pre-squash Gaussian (state independent)."""
    initial_action: float | None = None
    """If set, the actor's output bias is initialised so that the deterministic action of
    the untrained policy is this value (in action units, strictly inside the bounds), e.g. a
    known-good fixed gamma; ``None`` starts at the middle of the action range."""
    preference_sampling: str = "dirichlet"
    """``"dirichlet"``: draw a preference w per episode from a Dirichlet whose mean is
    the agent's preference; ``"fixed"``: always use the agent's preference."""
    dirichlet_concentration: float = 1.0
    """Concentration c of the preference Dirichlet, ``Dir(c * K * w)``. With a uniform
    w and c = 1 this is the uniform distribution on the simplex."""

    def __post_init__(self) -> None:
        if self.n_steps < 1 or self.batch_size < 1 or self.n_epochs < 1:
            raise ValueError("n_steps, batch_size and n_epochs must be positive")
        if not 0.0 < self.discount <= 1.0 or not 0.0 <= self.gae_lambda <= 1.0:
            raise ValueError("discount must lie in (0, 1] and gae_lambda in [0, 1]")
        if not 0.0 < self.mu_min <= self.mu_max:
            raise ValueError(f"need 0 < mu_min <= mu_max, got {self.mu_min}, {self.mu_max}")
        if not 0.0 <= self.maintenance <= 1.0:
            raise ValueError(f"maintenance must lie in [0, 1], got {self.maintenance}")
        if not 0.0 <= self.kappa < 1.0:
            raise ValueError(f"kappa must lie in [0, 1), got {self.kappa}")
        if self.scalarization not in ("stch", "linear"):
            raise ValueError(f"scalarization must be 'stch' or 'linear', got {self.scalarization!r}")
        if self.preference_sampling not in ("dirichlet", "fixed"):
            raise ValueError(
                f"preference_sampling must be 'dirichlet' or 'fixed', got {self.preference_sampling!r}"
            )
        if not 0.5 <= self.utopia_quantile <= 1.0:
            raise ValueError(f"utopia_quantile must lie in [0.5, 1], got {self.utopia_quantile}")
        if self.conflict_every < 1:
            raise ValueError("conflict_every must be >= 1")
        object.__setattr__(self, "hidden_sizes", tuple(int(h) for h in self.hidden_sizes))

    def to_dict(self) -> dict[str, Any]:
        """JSON-serialisable dictionary of the fields."""
        d = dataclasses.asdict(self)
        d["hidden_sizes"] = list(self.hidden_sizes)
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> PASTAConfig:
        """Inverse of :meth:`to_dict`; unknown keys raise ``ValueError``."""
        names = {f.name for f in dataclasses.fields(cls)}
        unknown = set(d) - names
        if unknown:
            raise ValueError(f"unknown PASTAConfig fields: {sorted(unknown)}")
        d = dict(d)
        if "hidden_sizes" in d:
            d["hidden_sizes"] = tuple(d["hidden_sizes"])
        return cls(**d)


def dataclass_field_docs(cls: type) -> dict[str, str]:
    """Attribute docstrings (the string literal under each field) of a dataclass.

    Used to build command-line help from the config classes. Returns an empty dict
    when the source is unavailable.
    """
    try:
        tree = ast.parse(inspect.getsource(cls).lstrip())
    except (OSError, TypeError, SyntaxError):
        return {}
    docs: dict[str, str] = {}
    body = tree.body[0].body if tree.body and isinstance(tree.body[0], ast.ClassDef) else []
    for node, nxt in zip(body, body[1:]):
        if (
            isinstance(node, ast.AnnAssign)
            and isinstance(node.target, ast.Name)
            and isinstance(nxt, ast.Expr)
            and isinstance(nxt.value, ast.Constant)
            and isinstance(nxt.value.value, str)
        ):
            docs[node.target.id] = " ".join(nxt.value.value.split())
    return docs


# --------------------------------------------------------------------------- pure pieces


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


def attention_weights(
    regret: np.ndarray, preference: np.ndarray, mu: float, maintenance: float
) -> np.ndarray:
    """Smooth-Tchebycheff attention over K objectives.

    ``alpha = (1 - maintenance) * softmax(w * regret / mu) + maintenance / K``,
    softmax over the last axis. As ``mu -> inf`` alpha becomes uniform; as
    ``mu -> 0`` it becomes one-hot on the largest weighted regret ``w_j regret_j``
    (mixed with the uniform floor ``maintenance / K``). Broadcasts over leading axes.
    """
    if mu <= 0:
        raise ValueError(f"mu must be positive, got {mu}")
    z = np.asarray(preference, dtype=np.float64) * np.asarray(regret, dtype=np.float64) / mu
    z = z - z.max(axis=-1, keepdims=True)
    e = np.exp(z)
    soft = e / e.sum(axis=-1, keepdims=True)
    k = soft.shape[-1]
    return (1.0 - maintenance) * soft + maintenance / k


@dataclass
class MuController:
    """Adaptive smoothing temperature of the Tchebycheff attention.

    Target at env step ``t`` with last measured conflict ratio ``c``::

        target = mu_max - (mu_max - mu_min) * min(t / decay_steps, 1)    (if decay)
        target += (mu_max - target) * (c - kappa) / (1 - kappa)          (if boost and c > kappa)
        mu     <- clip((1 - ema) * mu + ema * target, mu_min, mu_max)
    """

    mu_max: float = 10.0
    mu_min: float = 0.05
    ema: float = 0.05
    kappa: float = 0.4
    decay_steps: int = 1_000_000
    decay: bool = True
    conflict_boost: bool = True
    mu: float = field(default=float("nan"))

    def __post_init__(self) -> None:
        if math.isnan(self.mu):
            self.mu = self.mu_max

    @classmethod
    def from_config(cls, config: PASTAConfig) -> MuController:
        return cls(
            mu_max=config.mu_max,
            mu_min=config.mu_min,
            ema=config.mu_ema,
            kappa=config.kappa,
            decay_steps=config.mu_decay_steps,
            decay=config.mu_decay,
            conflict_boost=config.conflict_boost,
        )

    def target(self, step: int, conflict: float) -> float:
        """Target mu for env step ``step`` and conflict ratio ``conflict``."""
        frac = min(max(step, 0) / max(self.decay_steps, 1), 1.0) if self.decay else 0.0
        target = self.mu_max - (self.mu_max - self.mu_min) * frac
        if self.conflict_boost and conflict > self.kappa:
            target += (self.mu_max - target) * (conflict - self.kappa) / (1.0 - self.kappa)
        return target

    def update(self, step: int, conflict: float) -> float:
        """Move mu one EMA step towards its target and return it."""
        mu = (1.0 - self.ema) * self.mu + self.ema * self.target(step, conflict)
        self.mu = float(min(max(mu, self.mu_min), self.mu_max))
        return self.mu


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


class RunningMeanStd:
    """Running mean and variance (Chan et al. parallel Welford update)."""

    def __init__(self, shape: tuple[int, ...] = (), epsilon: float = 1e-4) -> None:
        self.mean = np.zeros(shape, dtype=np.float64)
        self.var = np.ones(shape, dtype=np.float64)
        self.count = float(epsilon)

    def update(self, x: np.ndarray) -> None:
        """Add a batch ``x`` of shape ``(n, *shape)``."""
        x = np.asarray(x, dtype=np.float64)
        batch_mean, batch_var, n = x.mean(axis=0), x.var(axis=0), x.shape[0]
        delta = batch_mean - self.mean
        total = self.count + n
        self.mean = self.mean + delta * n / total
        m2 = self.var * self.count + batch_var * n + delta**2 * self.count * n / total
        self.var = m2 / total
        self.count = total

    @property
    def std(self) -> np.ndarray:
        return np.sqrt(self.var + 1e-8)


# --------------------------------------------------------------------------- networks


def _layer(n_in: int, n_out: int, gain: float, gen: torch.Generator) -> nn.Linear:
    lin = nn.Linear(n_in, n_out)
    nn.init.orthogonal_(lin.weight, gain, generator=gen)
    nn.init.zeros_(lin.bias)
    return lin


def _mlp(sizes: list[int], out_gain: float, gen: torch.Generator) -> nn.Sequential:
    layers: list[nn.Module] = []
    for a, b in zip(sizes[:-2], sizes[1:-1]):
        layers += [_layer(a, b, math.sqrt(2.0), gen), nn.Tanh()]
    layers.append(_layer(sizes[-2], sizes[-1], out_gain, gen))
    return nn.Sequential(*layers)


class Actor(nn.Module):
    """Preference-conditioned Gaussian actor over the pre-squash variable u.

    Input ``[obs, w]``; ``mean_net`` is an MLP with tanh hidden layers; the
    log standard deviation is a state-independent parameter.
    """

    def __init__(self, in_dim: int, act_dim: int, hidden: tuple[int, ...], log_std_init: float,
                 gen: torch.Generator) -> None:
        super().__init__()
        self.mean_net = _mlp([in_dim, *hidden, act_dim], 0.01, gen)
        self.log_std = nn.Parameter(torch.full((act_dim,), float(log_std_init)))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.mean_net(x)


class BranchedCritic(nn.Module):
    """Shared tanh trunk on ``[obs, w]`` and one value head per objective.

    Head j is ``v_j = W2_j . tanh(W1_j z + b1_j) + b2_j`` on the trunk features z.
    The K heads are evaluated together: ``heads_hidden`` stacks the K first layers
    (rows ``j * head_hidden ... (j + 1) * head_hidden - 1`` belong to head j) and
    ``heads_out_weight[j]`` is the output layer of head j. With ``head_hidden = 0``
    each head is a single linear layer (row j of ``heads_linear``).
    """

    def __init__(self, in_dim: int, n_objectives: int, hidden: tuple[int, ...], head_hidden: int,
                 gen: torch.Generator) -> None:
        super().__init__()
        trunk: list[nn.Module] = []
        for a, b in zip([in_dim, *hidden[:-1]], hidden):
            trunk += [_layer(a, b, math.sqrt(2.0), gen), nn.Tanh()]
        self.trunk = nn.Sequential(*trunk)
        width = hidden[-1] if hidden else in_dim
        self.n_objectives, self.head_hidden = n_objectives, head_hidden
        if head_hidden > 0:
            self.heads_hidden = nn.Linear(width, n_objectives * head_hidden)
            with torch.no_grad():
                for j in range(n_objectives):
                    block = torch.empty(head_hidden, width)
                    nn.init.orthogonal_(block, math.sqrt(2.0), generator=gen)
                    self.heads_hidden.weight[j * head_hidden:(j + 1) * head_hidden] = block
                nn.init.zeros_(self.heads_hidden.bias)
            out = torch.empty(n_objectives, head_hidden)
            for j in range(n_objectives):
                nn.init.orthogonal_(out[j:j + 1], 1.0, generator=gen)
            self.heads_out_weight = nn.Parameter(out)
            self.heads_out_bias = nn.Parameter(torch.zeros(n_objectives))
        else:
            self.heads_linear = _layer(width, n_objectives, 1.0, gen)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        z = self.trunk(x)
        if self.head_hidden == 0:
            return self.heads_linear(z)
        h = torch.tanh(self.heads_hidden(z)).view(*z.shape[:-1], self.n_objectives, self.head_hidden)
        return (h * self.heads_out_weight).sum(dim=-1) + self.heads_out_bias


def _gaussian_log_prob(u: torch.Tensor, mean: torch.Tensor, log_std: torch.Tensor) -> torch.Tensor:
    z = (u - mean) * torch.exp(-log_std)
    return (-0.5 * z * z - log_std - 0.5 * math.log(2.0 * math.pi)).sum(-1)


def _log_abs_det_jacobian(u: torch.Tensor, scale: torch.Tensor) -> torch.Tensor:
    """log |da/du| of ``a = low + scale * sigmoid(u)``, summed over action dims."""
    return (torch.log(scale) - F.softplus(-u) - F.softplus(u)).sum(-1)


# --------------------------------------------------------------------------- buffer


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


_EPISODE_INFO_KEYS = ("is_success", "overtakes", "laps", "collision", "off_track")


def _info_item(infos: dict[str, Any], key: str, i: int) -> Any:
    if key not in infos:
        return None
    mask = infos.get("_" + key)
    if mask is not None and not bool(mask[i]):
        return None
    return infos[key][i]


# --------------------------------------------------------------------------- agent


class PASTA:
    """PASTA agent: collect rollouts, update, predict, save and load.

    Args:
        obs_dim: observation size.
        n_objectives: number of reward objectives K.
        action_low, action_high: bounds of the (box) action, e.g. ``[0.05]``, ``[1.0]``.
        config: hyper-parameters.
        preference: deployment preference w (K non-negative weights, normalised to
            sum 1); default uniform. Training samples per-episode preferences around
            it when ``config.preference_sampling == "dirichlet"``.
        seed: seed of the agent's generators (network init, sampling, minibatches)
            and of the first ``vec_env.reset``.
        objective_names: names of the objectives (stored in checkpoints).
    """

    def __init__(
        self,
        obs_dim: int,
        n_objectives: int,
        action_low: Any,
        action_high: Any,
        config: PASTAConfig | None = None,
        preference: Any = None,
        seed: int = 0,
        objective_names: Any = None,
    ) -> None:
        self.config = config if config is not None else PASTAConfig()
        self.obs_dim = int(obs_dim)
        self.n_objectives = int(n_objectives)
        self.action_low = np.asarray(action_low, dtype=np.float32).reshape(-1)
        self.action_high = np.asarray(action_high, dtype=np.float32).reshape(-1)
        if self.action_low.shape != self.action_high.shape or not np.all(self.action_high > self.action_low):
            raise ValueError(f"invalid action bounds {self.action_low}, {self.action_high}")
        self.act_dim = self.action_low.shape[0]
        self.preference = self._check_preference(preference)
        names = objective_names if objective_names is not None else [f"objective_{j}" for j in range(n_objectives)]
        self.objective_names = tuple(str(n) for n in names)
        if len(self.objective_names) != self.n_objectives:
            raise ValueError(f"{len(self.objective_names)} objective names for {n_objectives} objectives")
        self.seed = int(seed)

        seq = np.random.SeedSequence(self.seed)
        np_seed, torch_seed = seq.spawn(2)
        self.rng = np.random.default_rng(np_seed)
        self.torch_gen = torch.Generator().manual_seed(int(torch_seed.generate_state(1)[0]))

        cfg = self.config
        in_dim = self.obs_dim + self.n_objectives
        self.actor = Actor(in_dim, self.act_dim, cfg.hidden_sizes, cfg.log_std_init, self.torch_gen)
        if cfg.initial_action is not None:
            frac = (cfg.initial_action - self.action_low) / (self.action_high - self.action_low)
            if not np.all((frac > 0.0) & (frac < 1.0)):
                raise ValueError(f"initial_action {cfg.initial_action} must lie strictly inside the action bounds")
            with torch.no_grad():
                self.actor.mean_net[-1].bias.copy_(torch.as_tensor(np.log(frac / (1.0 - frac)), dtype=torch.float32))
        self.critic = BranchedCritic(in_dim, self.n_objectives, cfg.hidden_sizes, cfg.critic_head_hidden,
                                     self.torch_gen)
        self.optimizer = torch.optim.Adam(
            [{"params": self.actor.parameters()}, {"params": self.critic.parameters()}],
            lr=cfg.learning_rate,
            eps=cfg.adam_eps,
            fused=True,
        )
        self._low_t = torch.as_tensor(self.action_low)
        self._scale_t = torch.as_tensor(self.action_high - self.action_low)

        self.return_rms = RunningMeanStd(shape=(self.n_objectives,))
        self.mu_controller = MuController.from_config(cfg)
        self.utopia: np.ndarray | None = None
        self.last_conflict = 0.0
        self.num_timesteps = 0
        self.num_updates = 0
        self.train_time = 0.0
        self.metadata: dict[str, Any] = {}
        self.ep_info_buffer: deque[dict[str, Any]] = deque(maxlen=100)

        # rollout state (not saved)
        self._env_ref: Any = None
        self._last_obs: np.ndarray | None = None
        self._env_prefs: np.ndarray | None = None
        self._disc_returns: np.ndarray | None = None
        self._ep_returns: np.ndarray | None = None
        self._ep_lengths: np.ndarray | None = None

    # ----------------------------------------------------------------- helpers

    def _check_preference(self, preference: Any) -> np.ndarray:
        if preference is None:
            return np.full(self.n_objectives, 1.0 / self.n_objectives)
        w = np.asarray(preference, dtype=np.float64).reshape(-1)
        if w.shape != (self.n_objectives,) or np.any(w < 0) or not np.isfinite(w).all() or w.sum() <= 0:
            raise ValueError(f"preference must be {self.n_objectives} non-negative weights, got {preference}")
        return w / w.sum()

    def _sample_preferences(self, n: int) -> np.ndarray:
        if self.config.preference_sampling == "fixed":
            return np.tile(self.preference, (n, 1)).astype(np.float32)
        conc = self.config.dirichlet_concentration * self.n_objectives * np.maximum(self.preference, 1e-3)
        return self.rng.dirichlet(conc, size=n).astype(np.float32)

    def _inputs(self, obs: np.ndarray, prefs: np.ndarray) -> torch.Tensor:
        return torch.as_tensor(np.concatenate([obs, prefs], axis=-1), dtype=torch.float32)

    def _squash(self, u: torch.Tensor) -> torch.Tensor:
        return self._low_t + self._scale_t * torch.sigmoid(u)

    def _unsquash(self, action: torch.Tensor) -> torch.Tensor:
        p = ((action - self._low_t) / self._scale_t).clamp(1e-6, 1.0 - 1e-6)
        return torch.log(p) - torch.log1p(-p)

    def reconfigure(self, **changes: Any) -> None:
        """Change hyper-parameters of an existing agent (e.g. when resuming training).

        The optimiser's learning rate and the mu controller's bounds follow; the
        current mu is kept (clamped to the new bounds). Fields that change the network
        shapes cannot be changed.
        """
        fixed = {"hidden_sizes", "critic_head_hidden", "log_std_init"} & set(changes)
        if fixed:
            raise ValueError(f"cannot change {sorted(fixed)} of an existing agent")
        self.config = dataclasses.replace(self.config, **changes)
        for group in self.optimizer.param_groups:
            group["lr"] = self.config.learning_rate
            group["eps"] = self.config.adam_eps
        mu = self.mu_controller.mu
        self.mu_controller = MuController.from_config(self.config)
        self.mu_controller.mu = min(max(mu, self.config.mu_min), self.config.mu_max)

    def return_scale(self) -> np.ndarray:
        """Per-objective scale dividing the rewards (running std of discounted returns)."""
        if not self.config.normalize_returns:
            return np.ones(self.n_objectives)
        return self.return_rms.std

    # ----------------------------------------------------------------- inference

    def predict(self, obs: Any, deterministic: bool = True, preference: Any = None) -> np.ndarray:
        """Action(s) for ``obs`` of shape ``(obs_dim,)`` or ``(n, obs_dim)``.

        Returns an array of shape ``(act_dim,)`` or ``(n, act_dim)``. The deterministic
        action is the squashed mean. ``preference`` defaults to the agent's preference.
        """
        obs = np.asarray(obs, dtype=np.float32)
        single = obs.ndim == 1
        obs2 = obs.reshape(-1, self.obs_dim)
        w = self.preference if preference is None else self._check_preference(preference)
        x = self._inputs(obs2, np.tile(w, (obs2.shape[0], 1)))
        with torch.inference_mode():
            mean = self.actor(x)
            if deterministic:
                u = mean
            else:
                eps = torch.randn(mean.shape, generator=self.torch_gen)
                u = mean + torch.exp(self.actor.log_std) * eps
            a = self._squash(u).numpy()
        a = np.clip(a, self.action_low, self.action_high)
        return a[0] if single else a

    def log_prob(self, obs: Any, action: Any, preference: Any = None) -> np.ndarray:
        """Log-density of ``action`` (in action units, change of variables included)."""
        obs2 = np.asarray(obs, dtype=np.float32).reshape(-1, self.obs_dim)
        w = self.preference if preference is None else self._check_preference(preference)
        x = self._inputs(obs2, np.tile(w, (obs2.shape[0], 1)))
        a = torch.as_tensor(np.asarray(action, dtype=np.float32).reshape(-1, self.act_dim))
        with torch.inference_mode():
            u = self._unsquash(a)
            lp = _gaussian_log_prob(u, self.actor(x), self.actor.log_std)
            lp = lp - _log_abs_det_jacobian(u, self._scale_t)
        return lp.numpy()

    # ----------------------------------------------------------------- rollout

    def _reset_rollout_state(self, vec_env: Any) -> None:
        mode = vec_env.metadata.get("autoreset_mode")
        if mode is None or getattr(mode, "value", mode) != "SameStep":
            raise ValueError(
                "PASTA.collect needs a vector env created with "
                "autoreset_mode=gymnasium.vector.AutoresetMode.SAME_STEP "
                f"(got {mode!r}), so that the final observation of truncated episodes "
                "is available for bootstrapping"
            )
        n = vec_env.num_envs
        obs, _ = vec_env.reset(seed=self.seed + self.num_updates * 7919)
        self._env_ref = vec_env
        self._last_obs = np.asarray(obs, dtype=np.float32).reshape(n, self.obs_dim)
        self._env_prefs = self._sample_preferences(n)
        self._disc_returns = np.zeros((n, self.n_objectives))
        self._ep_returns = np.zeros((n, self.n_objectives))
        self._ep_lengths = np.zeros(n, dtype=np.int64)

    def _reward_vectors(self, rewards: Any, infos: dict[str, Any], done: np.ndarray) -> np.ndarray:
        n, k = done.shape[0], self.n_objectives
        r = np.asarray(rewards, dtype=np.float64)
        if r.shape == (n, k):
            return r
        if k == 1 and r.shape == (n,) and "reward_vector" not in infos and "final_info" not in infos:
            return r[:, None]
        out = np.empty((n, k))
        final = infos.get("final_info", {})
        for i in range(n):
            vec = _info_item(final, "reward_vector", i) if done[i] else None
            if vec is None:
                vec = _info_item(infos, "reward_vector", i)
            if vec is None:
                raise ValueError(
                    f"step returned rewards of shape {r.shape} and no info['reward_vector'] for env {i}; "
                    f"expected a reward vector of {k} objectives (wrap the env with "
                    "sofar_agents.wrappers.LinearReward to use a gymnasium vector env)"
                )
            out[i] = np.asarray(vec, dtype=np.float64).reshape(k)
        return out

    def collect(self, vec_env: Any, n_steps: int | None = None) -> RolloutBuffer:
        """Run the current stochastic policy for ``n_steps`` steps in every env.

        The env is reset on the first call (with the agent's seed) and whenever a
        different vector env is passed; otherwise collection continues from the
        last observation. Updates the return normaliser and ``num_timesteps``.
        """
        cfg = self.config
        t_steps = int(n_steps if n_steps is not None else cfg.n_steps)
        if self._env_ref is not vec_env or self._last_obs is None:
            self._reset_rollout_state(vec_env)
        assert self._last_obs is not None and self._env_prefs is not None
        assert self._disc_returns is not None and self._ep_returns is not None and self._ep_lengths is not None
        n, k = vec_env.num_envs, self.n_objectives

        obs_b = np.zeros((t_steps, n, self.obs_dim), dtype=np.float32)
        pref_b = np.zeros((t_steps, n, k), dtype=np.float32)
        u_b = np.zeros((t_steps, n, self.act_dim), dtype=np.float32)
        act_b = np.zeros((t_steps, n, self.act_dim), dtype=np.float32)
        logp_b = np.zeros((t_steps, n), dtype=np.float32)
        rew_b = np.zeros((t_steps, n, k))
        val_b = np.zeros((t_steps, n, k))
        next_val_b = np.zeros((t_steps, n, k))
        final_val = np.zeros((t_steps, n, k))
        term_b = np.zeros((t_steps, n), dtype=bool)
        trunc_b = np.zeros((t_steps, n), dtype=bool)
        episodes: list[dict[str, Any]] = []
        std = torch.exp(self.actor.log_std.detach())

        for t in range(t_steps):
            x = self._inputs(self._last_obs, self._env_prefs)
            with torch.no_grad():
                mean = self.actor(x)
                u = mean + std * torch.randn(mean.shape, generator=self.torch_gen)
                logp = _gaussian_log_prob(u, mean, self.actor.log_std)
                values = self.critic(x)
                action = self._squash(u)
            actions = np.clip(action.numpy(), self.action_low, self.action_high)
            next_obs, rewards, terminated, truncated, infos = vec_env.step(actions)
            terminated = np.asarray(terminated, dtype=bool).reshape(n)
            truncated = np.asarray(truncated, dtype=bool).reshape(n)
            done = terminated | truncated
            rvec = self._reward_vectors(rewards, infos, done)

            obs_b[t], pref_b[t], u_b[t], act_b[t] = self._last_obs, self._env_prefs, u.numpy(), actions
            logp_b[t], rew_b[t], val_b[t] = logp.numpy(), rvec, values.numpy()
            term_b[t], trunc_b[t] = terminated, truncated

            self._disc_returns = self._disc_returns * cfg.discount + rvec
            self.return_rms.update(self._disc_returns)
            self._ep_returns += rvec
            self._ep_lengths += 1

            boot = np.flatnonzero(truncated & ~terminated)
            if boot.size:
                final_obs = np.stack([np.asarray(infos["final_obs"][i], dtype=np.float32) for i in boot])
                with torch.no_grad():
                    final_val[t, boot] = self.critic(self._inputs(final_obs, self._env_prefs[boot])).numpy()

            if done.any():
                final_info = infos.get("final_info", {})
                idx = np.flatnonzero(done)
                for i in idx:
                    ep: dict[str, Any] = {
                        "returns": self._ep_returns[i].copy(),
                        "length": int(self._ep_lengths[i]),
                        "preference": self._env_prefs[i].copy(),
                    }
                    for key in _EPISODE_INFO_KEYS:
                        val = _info_item(final_info, key, i)
                        if val is not None:
                            ep[key] = float(val)
                    episodes.append(ep)
                    self.ep_info_buffer.append(ep)
                self._disc_returns[idx] = 0.0
                self._ep_returns[idx] = 0.0
                self._ep_lengths[idx] = 0
                self._env_prefs[idx] = self._sample_preferences(idx.size)
            self._last_obs = np.asarray(next_obs, dtype=np.float32).reshape(n, self.obs_dim)

        with torch.no_grad():
            last_values = self.critic(self._inputs(self._last_obs, self._env_prefs)).numpy()
        next_val_b[:-1] = val_b[1:]
        next_val_b[-1] = last_values
        ended = term_b | trunc_b
        next_val_b[ended] = final_val[ended]  # zero for terminated, V(final_obs) for truncated
        self.num_timesteps += t_steps * n
        return RolloutBuffer(obs_b, pref_b, u_b, act_b, logp_b, rew_b, val_b, next_val_b, term_b, trunc_b,
                             episodes)

    # ----------------------------------------------------------------- update

    def _regret(self, perf: np.ndarray, best: np.ndarray, scale: np.ndarray) -> np.ndarray:
        """Update the running utopia with this rollout's estimate ``best`` of the best
        achievable returns and return the regret of the performance ``perf`` (both in
        raw units): ``max(utopia - perf, 0) / scale + margin``, clipped."""
        cfg = self.config
        if self.utopia is None:
            self.utopia = best.copy()
        else:
            relaxed = self.utopia - cfg.utopia_decay * (self.utopia - best)
            self.utopia = np.maximum(best, relaxed)
        regret = np.maximum(self.utopia - perf, 0.0) / scale + cfg.utopia_margin
        return np.minimum(regret, cfg.regret_clip)

    def update(self, buffer: RolloutBuffer) -> dict[str, Any]:
        """One PASTA update (n_epochs of minibatch PPO) on a collected rollout.

        Returns a dictionary of statistics (scalars and per-objective arrays).
        """
        t_start = time.perf_counter()
        cfg = self.config
        k = self.n_objectives
        scale = self.return_scale()
        rewards = buffer.rewards / scale
        if cfg.reward_clip is not None:
            rewards = np.clip(rewards, -cfg.reward_clip, cfg.reward_clip)
        adv, ret = compute_gae(rewards, buffer.values, buffer.next_values, buffer.terminated, buffer.truncated,
                               cfg.discount, cfg.gae_lambda)

        flat_ret = ret.reshape(-1, k)
        perf = flat_ret.mean(axis=0) * scale  # mean lambda-return, raw units
        best = np.quantile(flat_ret, cfg.utopia_quantile, axis=0) * scale
        regret = self._regret(perf, best, scale)
        if cfg.fixed_mu is not None:
            mu = float(cfg.fixed_mu)
        else:
            mu = self.mu_controller.update(self.num_timesteps, self.last_conflict)

        b = buffer.obs.shape[0] * buffer.obs.shape[1]
        prefs = buffer.preferences.reshape(b, k).astype(np.float64)
        if cfg.scalarization == "linear":
            alpha = prefs
        else:
            alpha = attention_weights(regret[None, :], prefs, mu, cfg.maintenance)

        x_all = self._inputs(buffer.obs.reshape(b, self.obs_dim), buffer.preferences.reshape(b, k))
        u_all = torch.as_tensor(buffer.pre_actions.reshape(b, self.act_dim))
        logp_all = torch.as_tensor(buffer.log_probs.reshape(b))
        adv_all = torch.as_tensor(adv.reshape(b, k), dtype=torch.float32)
        ret_all = torch.as_tensor(ret.reshape(b, k), dtype=torch.float32)
        alpha_all = torch.as_tensor(alpha, dtype=torch.float32)

        actor_params = [p for p in self.actor.parameters()]
        critic_params = [p for p in self.critic.parameters()]
        log = {"policy_loss": [], "value_loss": [], "entropy": [], "approx_kl": [], "clipfrac": [],
               "conflict": []}
        continue_training = True
        n_mb = 0
        epochs_done = 0
        for _epoch in range(cfg.n_epochs):
            perm = self.rng.permutation(b)
            for start in range(0, b, cfg.batch_size):
                idx = torch.as_tensor(perm[start:start + cfg.batch_size])
                x, u, old_logp = x_all[idx], u_all[idx], logp_all[idx]
                a_mb, r_mb, al_mb = adv_all[idx], ret_all[idx], alpha_all[idx]

                mean = self.actor(x)
                log_std = self.actor.log_std
                new_logp = _gaussian_log_prob(u, mean, log_std)
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

                eps = torch.randn(mean.shape, generator=self.torch_gen)
                u_rep = mean + torch.exp(log_std) * eps
                gauss_ent = (0.5 + 0.5 * math.log(2.0 * math.pi) + log_std).sum()
                entropy = gauss_ent + _log_abs_det_jacobian(u_rep, self._scale_t).mean()

                self.optimizer.zero_grad(set_to_none=True)
                measure = cfg.pcgrad or n_mb % cfg.conflict_every == 0
                if measure:
                    grads = []
                    for j in range(k):
                        gj = torch.autograd.grad(per_obj_loss[j], actor_params, retain_graph=True,
                                                 allow_unused=True)
                        grads.append(torch.cat([(g if g is not None else torch.zeros_like(p)).reshape(-1)
                                                for g, p in zip(gj, actor_params)]))
                    g_mat = torch.stack(grads)
                    log["conflict"].append(gradient_conflict_ratio(g_mat))
                    if cfg.pcgrad:
                        g_mat = pcgrad_project(g_mat, self.rng)
                    (-cfg.ent_coef * entropy).backward()
                    offset = 0
                    g_sum = g_mat.sum(dim=0)
                    for p in actor_params:
                        n_el = p.numel()
                        g = g_sum[offset:offset + n_el].view_as(p)
                        p.grad = g.clone() if p.grad is None else p.grad + g
                        offset += n_el
                else:
                    (per_obj_loss.sum() - cfg.ent_coef * entropy).backward()

                values = self.critic(x)
                value_loss = 0.5 * ((values - r_mb) ** 2).sum(dim=-1).mean()
                (cfg.vf_coef * value_loss).backward()
                nn.utils.clip_grad_norm_(actor_params, cfg.max_grad_norm)
                nn.utils.clip_grad_norm_(critic_params, cfg.max_grad_norm)
                self.optimizer.step()
                n_mb += 1

                log["policy_loss"].append(float(per_obj_loss.detach().sum()))
                log["value_loss"].append(float(value_loss.detach()))
                log["entropy"].append(float(entropy.detach()))
                log["approx_kl"].append(approx_kl)
                log["clipfrac"].append(clipfrac)
            if not continue_training:
                break
            epochs_done += 1

        if log["conflict"]:
            self.last_conflict = float(np.mean(log["conflict"]))
        self.num_updates += 1
        self.train_time += time.perf_counter() - t_start

        v_pred = buffer.values.reshape(b, k)
        y = ret.reshape(b, k)
        var_y = y.var(axis=0)
        explained = np.where(var_y > 1e-12, 1.0 - (y - v_pred).var(axis=0) / np.maximum(var_y, 1e-12), np.nan)

        def _mean(key: str) -> float:
            return float(np.mean(log[key])) if log[key] else float("nan")

        return {
            "policy_loss": _mean("policy_loss"),
            "value_loss": _mean("value_loss"),
            "entropy": _mean("entropy"),
            "approx_kl": _mean("approx_kl"),
            "clipfrac": _mean("clipfrac"),
            "conflict_ratio": self.last_conflict,
            "mu": mu,
            "epochs": epochs_done,
            "minibatches": n_mb,
            "log_std": float(self.actor.log_std.detach().mean()),
            "attention": alpha.mean(axis=0),
            "regret": regret,
            "utopia": self.utopia.copy() if self.utopia is not None else None,
            "performance": perf,
            "return_scale": scale.copy(),
            "explained_variance": explained,
            "update_time": time.perf_counter() - t_start,
        }

    # ----------------------------------------------------------------- learn

    def learn(
        self,
        vec_env: Any,
        total_steps: int,
        callback: Callable[[PASTA, dict[str, Any]], bool | None] | None = None,
        log_interval: int = 1,
    ) -> PASTA:
        """Alternate :meth:`collect` and :meth:`update` for ``total_steps`` more env steps.

        After every update ``callback(agent, stats)`` is called with the update
        statistics plus ``rollout`` (the :class:`RolloutBuffer`) and ``episodes``; it
        may return ``False`` to stop. A summary is logged at INFO level every
        ``log_interval`` updates.
        """
        target = self.num_timesteps + int(total_steps)
        while self.num_timesteps < target:
            t0 = time.perf_counter()
            buffer = self.collect(vec_env, self.config.n_steps)
            t_collect = time.perf_counter() - t0
            stats = self.update(buffer)
            stats["collect_time"] = t_collect
            stats["sps"] = buffer.rewards.shape[0] * buffer.rewards.shape[1] / (time.perf_counter() - t0)
            stats["rollout"] = buffer
            stats["episodes"] = buffer.episodes
            if log_interval and self.num_updates % log_interval == 0:
                eps = buffer.episodes
                ret = np.mean([e["returns"] for e in eps], axis=0) if eps else None
                logger.info(
                    "update %d  steps %d  episodes %d  mean returns %s  mu %.3f  conflict %.2f  kl %.4f  sps %.0f",
                    self.num_updates, self.num_timesteps, len(eps),
                    np.array2string(ret, precision=3) if ret is not None else "-",
                    stats["mu"], stats["conflict_ratio"], stats["approx_kl"], stats["sps"],
                )
            if callback is not None and callback(self, stats) is False:
                break
        return self

    # ----------------------------------------------------------------- persistence

    def save(self, path: str | Path, metadata: dict[str, Any] | None = None) -> Path:
        """Write ``<stem>.pt`` (tensors only) and ``<stem>.json`` (everything else).

        ``path`` may end in ``.json``, ``.pt`` or have no such suffix. ``metadata``
        (e.g. the training command and env id) is merged into ``self.metadata`` and
        stored under ``"training"``. Returns the JSON path.
        """
        json_path, pt_path = checkpoint_paths(path)
        json_path.parent.mkdir(parents=True, exist_ok=True)
        if metadata:
            self.metadata.update(metadata)
        state = {
            "actor": self.actor.state_dict(),
            "critic": self.critic.state_dict(),
            "optimizer": self.optimizer.state_dict(),
            "return_rms_mean": torch.as_tensor(self.return_rms.mean),
            "return_rms_var": torch.as_tensor(self.return_rms.var),
            "return_rms_count": torch.tensor(self.return_rms.count, dtype=torch.float64),
        }
        if self.utopia is not None:
            state["utopia"] = torch.as_tensor(self.utopia)
        torch.save(state, pt_path)
        try:
            from importlib.metadata import version

            code_version = version("sofar")
        except Exception:  # noqa: BLE001 - not installed as a distribution
            code_version = "unknown"
        meta = {
            "format_version": FORMAT_VERSION,
            "algorithm": "PASTA",
            "weights_file": pt_path.name,
            "obs_dim": self.obs_dim,
            "n_objectives": self.n_objectives,
            "objective_names": list(self.objective_names),
            "act_dim": self.act_dim,
            "action_low": [float(str(v)) for v in self.action_low],
            "action_high": [float(str(v)) for v in self.action_high],
            "action_squashing": "sigmoid",
            "activation": "tanh",
            "preference": [float(v) for v in self.preference],
            "seed": self.seed,
            "config": self.config.to_dict(),
            "state": {
                "num_timesteps": self.num_timesteps,
                "num_updates": self.num_updates,
                "mu": self.mu_controller.mu,
                "last_conflict": self.last_conflict,
                "train_time_s": self.train_time,
            },
            "training": {
                **self.metadata,
                "code_version": code_version,
                "torch_version": torch.__version__,
                "saved_at": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
            },
        }
        json_path.write_text(json.dumps(meta, indent=2, default=_json_default))
        return json_path

    @classmethod
    def load(cls, path: str | Path) -> PASTA:
        """Load an agent written by :meth:`save` (``torch.load(weights_only=True)``)."""
        meta, json_path, pt_path = read_checkpoint_metadata(path)
        config = PASTAConfig.from_dict(meta["config"])
        agent = cls(
            meta["obs_dim"], meta["n_objectives"], meta["action_low"], meta["action_high"], config,
            preference=meta["preference"], seed=meta.get("seed", 0), objective_names=meta["objective_names"],
        )
        state = torch.load(pt_path, map_location="cpu", weights_only=True)
        validate_actor_state(
            {k: v.numpy() for k, v in state["actor"].items()}, meta, pt_path
        )
        try:
            agent.actor.load_state_dict(state["actor"])
            agent.critic.load_state_dict(state["critic"])
        except RuntimeError as err:
            raise ValueError(f"{pt_path}: weights do not match the configuration in {json_path}: {err}") from err
        if "optimizer" in state:
            agent.optimizer.load_state_dict(state["optimizer"])
        agent.return_rms.mean = state["return_rms_mean"].numpy().astype(np.float64)
        agent.return_rms.var = state["return_rms_var"].numpy().astype(np.float64)
        agent.return_rms.count = float(state["return_rms_count"])
        if "utopia" in state:
            agent.utopia = state["utopia"].numpy().astype(np.float64)
        st = meta.get("state", {})
        agent.num_timesteps = int(st.get("num_timesteps", 0))
        agent.num_updates = int(st.get("num_updates", 0))
        agent.mu_controller.mu = float(st.get("mu", config.mu_max))
        agent.last_conflict = float(st.get("last_conflict", 0.0))
        agent.train_time = float(st.get("train_time_s", 0.0))
        agent.metadata = copy.deepcopy(meta.get("training", {}))
        return agent


def _json_default(obj: Any) -> Any:
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, (np.floating, np.integer, np.bool_)):
        return obj.item()
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(f"{type(obj).__name__} is not JSON serialisable")
