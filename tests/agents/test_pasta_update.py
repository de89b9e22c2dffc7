"""The PPO epochs of an update: minibatch counts, early stop on KL and conflict measurement."""

from __future__ import annotations

import dataclasses

import numpy as np
import torch

from sofar_agents import PASTA, PASTAConfig
from sofar_agents.pasta.distribution import gaussian_log_prob
from sofar_agents.pasta.update import UpdateBatch, ppo_epochs


def _setup(**cfg: object) -> tuple[PASTA, UpdateBatch]:
    torch.set_num_threads(1)
    config = PASTAConfig(hidden_sizes=(8,), critic_head_hidden=0, n_epochs=3, batch_size=16, **cfg)
    agent = PASTA(3, 2, [0.05], [1.0], config, seed=0)
    g = torch.Generator().manual_seed(2)
    x = torch.randn(40, 5, generator=g)
    with torch.no_grad():  # a rollout of the current policy: its first minibatch is on-policy
        u = agent.actor(x) + 0.3 * torch.randn(40, 1, generator=g)
        logp = gaussian_log_prob(u, agent.actor(x), agent.actor.log_std)
    batch = UpdateBatch(x, u, logp, torch.randn(40, 2, generator=g), torch.randn(40, 2, generator=g),
                        torch.full((40, 2), 0.5))
    return agent, batch


def _run(agent: PASTA, batch: UpdateBatch, config: PASTAConfig) -> tuple[dict, int, int]:
    return ppo_epochs(agent.actor, agent.critic, agent.optimizer, agent.squash, batch, config, agent.rng,
                      agent.torch_gen)


def test_epochs_minibatches_and_conflict_every() -> None:
    agent, batch = _setup(conflict_every=2)
    before = [p.detach().clone() for p in agent.actor.parameters()]
    log, n_mb, epochs = _run(agent, batch, agent.config)
    assert (n_mb, epochs) == (9, 3)  # 3 minibatches (16, 16, 8) per epoch
    assert len(log["policy_loss"]) == 9 and len(log["conflict"]) == 5  # minibatches 0, 2, 4, 6, 8
    assert all(0.0 <= c <= 1.0 for c in log["conflict"])
    assert any(not torch.equal(a, b) for a, b in zip(before, agent.actor.parameters()))


def test_early_stop_on_kl() -> None:
    agent, batch = _setup(learning_rate=0.05)
    cfg = dataclasses.replace(agent.config, target_kl=1e-9)
    log, n_mb, epochs = _run(agent, batch, cfg)
    # the first minibatch is on-policy (KL 0) and steps; the second one exceeds the target
    assert (n_mb, epochs) == (1, 0)
    assert abs(log["approx_kl"][0]) < 1e-6
    assert np.isfinite(log["value_loss"][0])
