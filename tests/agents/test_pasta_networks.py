"""The actor and the branched critic: shapes, head independence and reproducible initialisation."""

from __future__ import annotations

import numpy as np
import torch

from sofar_agents.pasta.networks import Actor, BranchedCritic, network_inputs


def test_network_inputs() -> None:
    x = network_inputs(np.ones((3, 2), np.float32), np.full((3, 4), 0.25))
    assert x.shape == (3, 6) and x.dtype == torch.float32


def test_shapes_and_reproducible_init() -> None:
    a1 = Actor(7, 1, (16, 16), -0.5, torch.Generator().manual_seed(0))
    a2 = Actor(7, 1, (16, 16), -0.5, torch.Generator().manual_seed(0))
    x = torch.randn(5, 7, generator=torch.Generator().manual_seed(1))
    assert a1(x).shape == (5, 1)
    torch.testing.assert_close(a1(x), a2(x), rtol=0, atol=0)
    torch.testing.assert_close(a1.log_std, torch.tensor([-0.5]))
    for head_hidden in (0, 8):
        critic = BranchedCritic(7, 3, (16,), head_hidden, torch.Generator().manual_seed(0))
        assert critic(x).shape == (5, 3)


def test_critic_heads_are_independent() -> None:
    critic = BranchedCritic(4, 3, (8,), 6, torch.Generator().manual_seed(0))
    x = torch.randn(2, 4, generator=torch.Generator().manual_seed(1))
    before = critic(x).detach()
    with torch.no_grad():
        critic.heads_hidden.weight[6:12] += 1.0  # rows of head 1
        critic.heads_out_bias[1] += 1.0
    after = critic(x).detach()
    torch.testing.assert_close(after[:, [0, 2]], before[:, [0, 2]])
    assert not torch.allclose(after[:, 1], before[:, 1])
