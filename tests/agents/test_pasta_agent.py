"""The PASTA agent: inference, determinism, initial action and reconfiguration."""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import torch

from sofar_agents import PASTA, PASTAConfig
from sofar_agents.wrappers import LinearReward
from synthetic_envs import SyntheticRace


def _obs(n: int = 32) -> np.ndarray:
    return np.random.default_rng(0).uniform(-1, 1, size=(n, 12)).astype(np.float32)


def test_stochastic_actions_within_bounds_and_log_prob(trained: tuple[PASTA, Path]) -> None:
    agent, _ = trained
    obs = _obs(256)
    a = agent.predict(obs, deterministic=False)
    assert np.all((a >= 0.05) & (a <= 1.0))
    # The density over gamma integrates to one (change of variables included).
    grid = np.linspace(0.05 + 1e-5, 1.0 - 1e-5, 20001)
    dens = np.exp(agent.log_prob(np.repeat(obs[:1], grid.size, axis=0), grid))
    assert np.trapezoid(dens, grid) == pytest.approx(1.0, abs=1e-3)


def test_predict_shapes_and_preference(trained: tuple[PASTA, Path]) -> None:
    agent, _ = trained
    obs = _obs(4)
    assert agent.predict(obs).shape == (4, 1) and agent.predict(obs[0]).shape == (1,)
    np.testing.assert_array_equal(agent.predict(obs[0]), agent.predict(obs)[0])
    with pytest.raises(ValueError, match="non-negative weights"):
        agent.predict(obs, preference=[1, 0, 0])


def test_training_is_deterministic() -> None:
    torch.set_num_threads(1)

    def run() -> tuple[np.ndarray, np.ndarray]:
        venv = gym.vector.SyncVectorEnv([lambda: LinearReward(SyntheticRace()) for _ in range(2)],
                                        autoreset_mode=gym.vector.AutoresetMode.SAME_STEP)
        config = PASTAConfig(n_steps=32, n_epochs=2, hidden_sizes=(16,), critic_head_hidden=0)
        agent = PASTA(12, 5, [0.05], [1.0], config, seed=11)
        buf = agent.collect(venv, 32)
        agent.update(buf)
        venv.close()
        return buf.actions, agent.predict(_obs())

    (a1, p1), (a2, p2) = run(), run()
    np.testing.assert_array_equal(a1, a2)
    np.testing.assert_array_equal(p1, p2)


def test_initial_action_sets_the_untrained_deterministic_action() -> None:
    agent = PASTA(12, 5, [0.05], [1.0], PASTAConfig(initial_action=0.15, hidden_sizes=(16, 16)), seed=0)
    np.testing.assert_allclose(agent.predict(np.zeros((2, 12), np.float32), deterministic=True), 0.15, atol=2e-3)
    with pytest.raises(ValueError, match="inside the action bounds"):
        PASTA(12, 5, [0.05], [1.0], PASTAConfig(initial_action=1.0, hidden_sizes=(16, 16)), seed=0)


def test_sample_preferences() -> None:
    cfg = PASTAConfig(hidden_sizes=(8,), critic_head_hidden=0)
    agent = PASTA(12, 5, [0.05], [1.0], cfg, preference=[1, 1, 1, 1, 4], seed=0)
    w = agent.sample_preferences(2000)
    assert w.shape == (2000, 5) and w.dtype == np.float32
    np.testing.assert_allclose(w.sum(axis=1), 1.0, atol=1e-5)
    np.testing.assert_allclose(w.mean(axis=0), agent.preference, atol=0.02)  # Dirichlet mean = preference
    fixed = PASTA(12, 5, [0.05], [1.0], PASTAConfig(hidden_sizes=(8,), preference_sampling="fixed"), seed=0)
    np.testing.assert_allclose(fixed.sample_preferences(3), np.full((3, 5), 0.2))


def test_trade_off_sampling_draws_the_safety_overtakes_path_uniformly() -> None:
    cfg = PASTAConfig(hidden_sizes=(8,), critic_head_hidden=0, preference_sampling="trade-off")
    rest = 0.1 / 3
    agent = PASTA(12, 5, [0.05], [1.0], cfg, preference=[0.5, 0.4, rest, rest, rest], seed=0)
    w = agent.sample_preferences(4000).astype(np.float64)
    np.testing.assert_allclose(w[:, 2:], rest, atol=1e-6)  # the other objectives keep their weights
    np.testing.assert_allclose(w[:, 0] + w[:, 1], 0.9, atol=1e-6)  # the first two split what is left
    counts, _ = np.histogram(w[:, 0], bins=9, range=(0.0, 0.9))
    assert counts.min() > 0.8 * 4000 / 9  # uniform, ends included (a Dirichlet starves them)
    assert w[:, 0].min() < 0.01 and w[:, 0].max() > 0.89


def test_trade_off_sampling_needs_weight_on_the_first_two_objectives() -> None:
    cfg = PASTAConfig(hidden_sizes=(8,), critic_head_hidden=0, preference_sampling="trade-off")
    with pytest.raises(ValueError, match="trade-off"):
        PASTA(12, 5, [0.05], [1.0], cfg, preference=[0, 0, 1, 1, 1], seed=0)


def test_reconfigure_keeps_mu_and_refuses_shape_changes() -> None:
    agent = PASTA(12, 5, [0.05], [1.0], PASTAConfig(hidden_sizes=(8,), critic_head_hidden=0), seed=0)
    agent.mu_controller.mu = 3.0
    agent.reconfigure(learning_rate=1e-4, mu_max=2.0)
    assert agent.config.learning_rate == 1e-4
    assert all(g["lr"] == 1e-4 for g in agent.optimizer.param_groups)
    assert agent.mu_controller.mu == 2.0 and agent.mu_controller.mu_max == 2.0  # clamped to the new bound
    with pytest.raises(ValueError, match="hidden_sizes"):
        agent.reconfigure(hidden_sizes=(16,))
