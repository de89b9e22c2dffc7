"""Which objective pushes PASTA's gamma which way, at which preference.

PASTA's actor loss is ``-sum_j mean_b alpha_bj * r_b * A_bj`` (before clipping), so at the collection policy
the gradient of objective ``j`` with respect to the actor's mean action ``m_b`` is
``alpha_bj * A_bj * d log pi(u_b) / d m_b = alpha_bj * A_bj * (u_b - m_b) / sigma**2``. Averaged over a
rollout, its sign says whether objective ``j`` currently asks for a higher (``+``) or a lower (``-``)
gamma, and its size how hard, in the same units for every objective. Grouping the transitions by the
safety weight of the preference they were driven with shows whether the safety-first and the pace-first
preferences are pulled apart, and by which objective.

:func:`objective_push` computes the targets as :meth:`PASTA.update` does (:meth:`PASTA.advantages`,
regret against the agent's utopia, smooth-Tchebycheff attention at the agent's mu), without moving the
agent's utopia, mu or weights. The advantages are centred per objective (as a PPO minibatch is);
the common scale of the minibatch normalisation is left out, since it does not change a sign or a ratio.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from sofar_agents.pasta.attention import attention_weights, normalised_regret

__all__ = ["SAFETY_BINS", "PushBin", "objective_push", "pool_bins", "push_table"]

SAFETY_BINS: tuple[tuple[float, float], ...] = ((0.0, 0.3), (0.3, 0.6), (0.6, 1.0))
"""Default bins of the safety weight (the first objective's weight), upper bound excluded."""


@dataclass(frozen=True)
class PushBin:
    """The push of every objective on the mean action over the transitions of one safety-weight bin."""

    low: float
    high: float
    n: int
    """Transitions in the bin."""
    mean_action: float
    """Mean of the actor's deterministic action over them (pre-squash, action units)."""
    attention: np.ndarray
    """Mean attention weight of each objective, ``(K,)``."""
    push: np.ndarray
    """Mean ``alpha_j * A_j * (u - m) / sigma**2`` of each objective, ``(K,)`` (see the module doc)."""


def objective_push(agent: Any, buffer: Any, bins: Sequence[tuple[float, float]] = SAFETY_BINS) -> list[PushBin]:
    """The per-objective push on the mean action of ``agent`` (a PASTA) over one rollout ``buffer``.

    ``buffer`` is a :class:`~sofar_agents.pasta.buffer.RolloutBuffer` collected with ``agent``'s
    current policy (its pre-squash samples ``u``). One-dimensional actions only. Bins without a
    transition are left out.
    """
    import torch

    from sofar_agents.pasta.networks import network_inputs

    if agent.act_dim != 1:
        raise ValueError(f"objective_push needs a one-dimensional action, got {agent.act_dim}")
    cfg, k = agent.config, agent.n_objectives
    adv, ret, scale = agent.advantages(buffer)
    b = buffer.obs.shape[0] * buffer.obs.shape[1]
    prefs = buffer.preferences.reshape(b, k).astype(np.float64)
    if cfg.scalarization == "linear":
        alpha = prefs
    else:
        flat = ret.reshape(-1, k)
        perf = flat.mean(axis=0) * scale
        utopia = agent.utopia if agent.utopia is not None else np.quantile(flat, cfg.utopia_quantile, axis=0) * scale
        regret = normalised_regret(perf, utopia, scale, cfg.utopia_margin, cfg.regret_clip)
        mu = float(cfg.fixed_mu) if cfg.fixed_mu is not None else float(agent.mu_controller.mu)
        alpha = attention_weights(regret[None, :], prefs, mu, cfg.maintenance)
    a = adv.reshape(b, k)
    a = a - a.mean(axis=0)
    with torch.no_grad():
        inputs = network_inputs(buffer.obs.reshape(b, agent.obs_dim), buffer.preferences.reshape(b, k))
        mean = agent.actor(inputs).numpy().reshape(b).astype(np.float64)
        sigma = float(np.exp(agent.actor.log_std.detach().numpy().reshape(-1)[0]))
    score = (buffer.pre_actions.reshape(b).astype(np.float64) - mean) / sigma ** 2
    contrib = alpha * a * score[:, None]
    out = []
    for low, high in bins:
        m = (prefs[:, 0] >= low) & (prefs[:, 0] < high)
        if m.any():
            out.append(PushBin(float(low), float(high), int(m.sum()), float(mean[m].mean()),
                               alpha[m].mean(axis=0), contrib[m].mean(axis=0)))
    return out


def pool_bins(runs: Sequence[Sequence[PushBin]]) -> list[PushBin]:
    """Transition-weighted pool of the bins of several rollouts (bins matched by their bounds)."""
    pooled: dict[tuple[float, float], list[PushBin]] = {}
    for run in runs:
        for pb in run:
            pooled.setdefault((pb.low, pb.high), []).append(pb)
    out = []
    for (low, high), items in sorted(pooled.items()):
        n = sum(p.n for p in items)
        w = np.array([p.n for p in items], dtype=np.float64) / n
        out.append(PushBin(low, high, n, float(sum(wi * p.mean_action for wi, p in zip(w, items))),
                           sum(wi * p.attention for wi, p in zip(w, items)),
                           sum(wi * p.push for wi, p in zip(w, items))))
    return out


def push_table(bins: Sequence[PushBin], names: Sequence[str]) -> str:
    """Markdown: per safety-weight bin, the mean action, then each objective's attention and push."""
    head = "| safety weight | transitions | mean gamma | " + " | ".join(f"{n}: alpha, push" for n in names) \
        + " | total push |\n"
    head += "|---|---:|---:|" + "---:|" * len(names) + "---:|\n"
    rows = []
    for pb in bins:
        cells = " | ".join(f"{al:.2f}, {p:+.4f}" for al, p in zip(pb.attention, pb.push))
        rows.append(f"| [{pb.low:g}, {pb.high:g}) | {pb.n} | {pb.mean_action:.3f} | {cells} | {pb.push.sum():+.4f} |")
    return head + "\n".join(rows) + "\n"
