"""The PASTA networks: preference-conditioned actor and branched multi-objective critic.

Both take ``[obs, w]`` (the observation followed by the K preference weights, see
:func:`network_inputs`). Weights are initialised orthogonally from a
``torch.Generator`` so that construction is reproducible without the global RNG.
"""

from __future__ import annotations

import math

import numpy as np
import torch
from torch import nn

__all__ = ["Actor", "BranchedCritic", "network_inputs"]


def network_inputs(obs: np.ndarray, prefs: np.ndarray) -> torch.Tensor:
    """``[obs, w]`` along the last axis as a float32 tensor (the input of both networks)."""
    return torch.as_tensor(np.concatenate([obs, prefs], axis=-1), dtype=torch.float32)


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
