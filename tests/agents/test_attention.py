"""Smooth-Tchebycheff attention, the mu controller, conflict ratio and PCGrad."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from sofar_agents.pasta import MuController, PASTAConfig, attention_weights, gradient_conflict_ratio, pcgrad_project

REGRET = np.array([0.5, 2.0, 1.0, 0.1])
PREF = np.array([0.4, 0.1, 0.3, 0.2])  # weighted regret 0.2, 0.2, 0.3, 0.02 -> objective 2 largest


def test_attention_is_a_distribution_with_floor() -> None:
    for mu in (1e-3, 0.05, 1.0, 100.0):
        a = attention_weights(REGRET, PREF, mu, maintenance=0.15)
        assert a.sum() == pytest.approx(1.0)
        assert np.all(a >= 0.15 / 4 - 1e-12)


def test_attention_uniform_as_mu_grows() -> None:
    a = attention_weights(REGRET, PREF, 1e6, maintenance=0.15)
    np.testing.assert_allclose(a, 0.25, atol=1e-6)


def test_attention_one_hot_on_largest_weighted_regret_as_mu_vanishes() -> None:
    m = 0.15
    a = attention_weights(REGRET, PREF, 1e-4, maintenance=m)
    expected = np.full(4, m / 4)
    expected[2] += 1.0 - m
    np.testing.assert_allclose(a, expected, atol=1e-9)
    # Without maintenance: exactly one-hot.
    np.testing.assert_allclose(attention_weights(REGRET, PREF, 1e-4, maintenance=0.0), np.eye(4)[2], atol=1e-9)


def test_attention_matches_formula_and_broadcasts() -> None:
    mu, m = 0.3, 0.15
    z = PREF * REGRET / mu
    soft = np.exp(z) / np.exp(z).sum()
    np.testing.assert_allclose(attention_weights(REGRET, PREF, mu, m), (1 - m) * soft + m / 4)
    prefs = np.stack([PREF, np.full(4, 0.25)])
    out = attention_weights(REGRET[None], prefs, mu, m)
    assert out.shape == (2, 4)
    np.testing.assert_allclose(out[0], attention_weights(REGRET, PREF, mu, m))
    with pytest.raises(ValueError):
        attention_weights(REGRET, PREF, 0.0, m)


def test_mu_target_schedule_and_conflict_boost() -> None:
    c = MuController(mu_max=10.0, mu_min=0.05, ema=0.05, kappa=0.4, decay_steps=1000)
    assert c.target(0, 0.0) == pytest.approx(10.0)
    assert c.target(500, 0.0) == pytest.approx(10.0 - 0.5 * 9.95)
    assert c.target(1000, 0.0) == pytest.approx(0.05)
    assert c.target(5000, 0.0) == pytest.approx(0.05)  # clamped after the decay
    assert c.target(1000, 0.4) == pytest.approx(0.05)  # at the threshold: no push
    assert c.target(1000, 0.7) == pytest.approx(0.05 + 0.5 * 9.95)  # halfway between kappa and 1
    assert c.target(1000, 1.0) == pytest.approx(10.0)
    assert c.target(500, 0.7) == pytest.approx(c.target(500, 0.0) + 0.5 * (10.0 - c.target(500, 0.0)))
    off = MuController(decay_steps=1000, decay=False, conflict_boost=False)
    assert off.target(1000, 1.0) == pytest.approx(off.mu_max)


def test_mu_controller_ema_and_clamp() -> None:
    c = MuController.from_config(PASTAConfig(mu_decay_steps=1000))
    assert c.mu == pytest.approx(10.0)
    mu1 = c.update(1000, 0.0)
    assert mu1 == pytest.approx(0.95 * 10.0 + 0.05 * 0.05)
    for _ in range(400):
        c.update(2000, 0.0)
    assert c.mu == pytest.approx(0.05, abs=1e-6)
    assert c.mu >= 0.05
    # Persistent conflict pushes mu back up to mu_max.
    for _ in range(400):
        c.update(2000, 1.0)
    assert c.mu == pytest.approx(10.0, abs=1e-5)


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
