"""Smooth-Tchebycheff attention: utopia, regret, attention weights and the mu controller."""

from __future__ import annotations

import numpy as np
import pytest

from sofar_agents.pasta import MuController, PASTAConfig, attention_weights
from sofar_agents.pasta.attention import normalised_regret, update_utopia

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
    c = MuController.from_config(PASTAConfig(mu_decay_steps=1000, mu_max=10.0))
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


def test_default_temperature_keeps_the_preference_in_the_attention() -> None:
    """At the default mu range the attention follows the preference: the safety-first and the pace-first
    preference put most of the weight on different objectives (at the reference's mu of 10 both are
    nearly uniform)."""
    cfg = PASTAConfig()
    regret = np.array([1.2, 1.8, 1.0, 1.7, 0.5])  # regrets of the order training logs show
    safety, pace = np.array([0.9, 0.0, 0.1 / 3, 0.1 / 3, 0.1 / 3]), np.array([0.1, 0.8, 0.1 / 3, 0.1 / 3, 0.1 / 3])
    for mu in (cfg.mu_min, cfg.mu_max):
        a_safe = attention_weights(regret, safety, mu, cfg.maintenance)
        a_pace = attention_weights(regret, pace, mu, cfg.maintenance)
        assert int(np.argmax(a_safe)) == 0 and int(np.argmax(a_pace)) == 1
        assert a_safe[0] - a_pace[0] > 0.5
    flat = attention_weights(regret, safety, 10.0, cfg.maintenance) - attention_weights(regret, pace, 10.0,
                                                                                         cfg.maintenance)
    assert np.abs(flat).max() < 0.05


def test_utopia_is_a_slowly_relaxing_running_maximum() -> None:
    first = np.array([1.0, -2.0])
    u = update_utopia(None, first, decay=0.1)
    np.testing.assert_array_equal(u, first)
    assert u is not first  # a copy
    u = update_utopia(u, np.array([3.0, -4.0]), decay=0.1)  # up at once, down by 10 % of the gap
    np.testing.assert_allclose(u, [3.0, -2.2])
    np.testing.assert_allclose(update_utopia(u, np.array([0.0, -5.0]), decay=0.0), u)  # plain maximum


def test_normalised_regret() -> None:
    utopia, scale = np.array([2.0, 1.0, 0.0]), np.array([2.0, 1.0, 0.5])
    perf = np.array([1.0, 3.0, -100.0])
    r = normalised_regret(perf, utopia, scale, margin=0.1, clip=10.0)
    # shortfall / scale + margin; no negative regret above the utopia; clipped
    np.testing.assert_allclose(r, [0.6, 0.1, 10.0])
