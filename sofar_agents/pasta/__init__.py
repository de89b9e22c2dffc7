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

Action squashing: the actor is a Gaussian over a pre-activation ``u``. By default
(``action_squashing="sigmoid"``) the action is ``a = low + (high - low) * sigmoid(u)``;
the PPO ratio is computed on ``u`` (the change-of-variables term cancels in the
ratio); :meth:`PASTA.log_prob` returns the log-density of ``a`` including
``-log|da/du|``. The deterministic action is the squashed mean (the median of the
squashed distribution). The entropy bonus is the entropy of the squashed
distribution, estimated with one reparameterised sample per state. With
``action_squashing="clip"`` ``u`` is in action units and ``a = clip(u, low, high)``
(the reference's ``gamma = 0.05 + 0.95 mu``, clipped): a censored Gaussian whose
deterministic action reaches a bound exactly; the entropy bonus is that of ``u``.

Rollouts are collected from a Gymnasium vector environment created with
``autoreset_mode=AutoresetMode.SAME_STEP``; all randomness comes from generators
owned by the agent and derived from its seed.

Modules: :mod:`~sofar_agents.pasta.config` (hyper-parameters),
:mod:`~sofar_agents.pasta.gae` (advantages), :mod:`~sofar_agents.pasta.running_stats`
(return scale), :mod:`~sofar_agents.pasta.attention` (regret, attention weights, mu
controller), :mod:`~sofar_agents.pasta.gradients` (per-objective gradients, conflict,
PCGrad), :mod:`~sofar_agents.pasta.networks` (actor, branched critic),
:mod:`~sofar_agents.pasta.distribution` (squashed Gaussian),
:mod:`~sofar_agents.pasta.buffer` and :mod:`~sofar_agents.pasta.rollout` (rollouts),
:mod:`~sofar_agents.pasta.update` (PPO epochs), :mod:`~sofar_agents.pasta.agent` (the
:class:`PASTA` class) and :mod:`~sofar_agents.pasta.checkpoint` (the checkpoint format).

The names below are imported lazily, so that importing a torch-free submodule (the
config or the checkpoint reader used by :mod:`sofar_agents.policies`) does not import
torch.
"""


from __future__ import annotations

import importlib
from typing import Any

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

_LAZY = {
    "PASTA": "sofar_agents.pasta.agent",
    "PASTAConfig": "sofar_agents.pasta.config",
    "RolloutBuffer": "sofar_agents.pasta.buffer",
    "RunningMeanStd": "sofar_agents.pasta.running_stats",
    "MuController": "sofar_agents.pasta.attention",
    "compute_gae": "sofar_agents.pasta.gae",
    "attention_weights": "sofar_agents.pasta.attention",
    "gradient_conflict_ratio": "sofar_agents.pasta.gradients",
    "pcgrad_project": "sofar_agents.pasta.gradients",
    "dataclass_field_docs": "sofar_agents.cli",
}


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'sofar_agents.pasta' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(list(globals()) + __all__)
