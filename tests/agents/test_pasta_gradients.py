"""Per-objective gradients: extraction, accumulation, conflict ratio and PCGrad."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from sofar_agents.pasta import gradient_conflict_ratio, pcgrad_project
from sofar_agents.pasta.gradients import add_flat_gradient, objective_gradients


def test_objective_gradients_and_accumulation() -> None:
    w = torch.nn.Parameter(torch.tensor([1.0, 2.0]))
    b = torch.nn.Parameter(torch.tensor(3.0))
    unused = torch.nn.Parameter(torch.tensor([5.0]))
    params = [w, b, unused]
    losses = torch.stack([(w * w).sum(), w[0] * b])
    g = objective_gradients(losses, params)
    # rows: d/d(w0, w1, b, unused) of each loss
    torch.testing.assert_close(g, torch.tensor([[2.0, 4.0, 0.0, 0.0], [3.0, 0.0, 1.0, 0.0]]))
    assert all(p.grad is None for p in params)
    losses.sum().backward()  # the graph was retained
    add_flat_gradient(params, g.sum(dim=0))
    torch.testing.assert_close(w.grad, torch.tensor([10.0, 8.0]))  # backward + added
    torch.testing.assert_close(b.grad, torch.tensor(2.0))
    torch.testing.assert_close(unused.grad, torch.tensor([0.0]))  # created where backward left None


def test_gradient_conflict_ratio() -> None:
    g = torch.tensor([[1.0, 0.0], [-1.0, 0.1], [0.0, 1.0]])
    # pairs: (0,1) negative, (0,2) zero (not a conflict), (1,2) positive
    assert gradient_conflict_ratio(g) == pytest.approx(1 / 3)
    assert gradient_conflict_ratio(torch.tensor([[1.0, 0.0], [-1.0, 0.0], [0.0, 0.0]])) == pytest.approx(1.0)
    assert gradient_conflict_ratio(torch.tensor([[1.0, 2.0]])) == 0.0


def test_pcgrad_projects_each_gradient_against_the_others() -> None:
    rng = np.random.default_rng(0)
    g = torch.tensor([[1.0, 0.0], [-1.0, 1.0], [0.0, 2.0]])
    out = pcgrad_project(g, rng)
    # g0 conflicts only with g1: projected onto the normal plane of g1.
    g0 = g[0] - torch.dot(g[0], g[1]) / torch.dot(g[1], g[1]) * g[1]
    torch.testing.assert_close(out[0], g0)
    assert torch.dot(out[0], g[1]) == pytest.approx(0.0, abs=1e-6)
    # g1 conflicts with g0 only.
    g1 = g[1] - torch.dot(g[1], g[0]) / torch.dot(g[0], g[0]) * g[0]
    torch.testing.assert_close(out[1], g1)
    # g2 conflicts with nobody: unchanged.
    torch.testing.assert_close(out[2], g[2])
    # Never projected against itself.
    torch.testing.assert_close(pcgrad_project(g[:1], rng), g[:1])
    # After projection, no projected gradient conflicts with any original one (two objectives).
    two = torch.randn(2, 50, generator=torch.Generator().manual_seed(1))
    two[1] = -two[0] + 0.1 * two[1]
    proj = pcgrad_project(two, rng)
    assert torch.dot(proj[0], two[1]) >= -1e-5 and torch.dot(proj[1], two[0]) >= -1e-5
