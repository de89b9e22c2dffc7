"""The per-objective push on PASTA's mean action: signs and bins on a rollout with known advantages."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from sofar_agents.evaluation.objective_push import objective_push, pool_bins, push_table
from sofar_agents.pasta import PASTA, PASTAConfig
from sofar_agents.pasta.buffer import RolloutBuffer
from sofar_agents.pasta.networks import network_inputs


def _buffer(agent: PASTA, t: int, safety_weight: np.ndarray, rng: np.random.Generator) -> RolloutBuffer:
    """One-step episodes (advantage = reward), rewards built from the sampled action's deviation."""
    k = agent.n_objectives
    obs = rng.normal(size=(t, 1, agent.obs_dim)).astype(np.float32)
    prefs = np.zeros((t, 1, k), np.float32)
    prefs[:, 0, 0] = safety_weight
    prefs[:, 0, 1] = 1.0 - safety_weight
    with torch.no_grad():
        mean = agent.actor(network_inputs(obs.reshape(t, -1), prefs.reshape(t, k))).numpy().reshape(t)
    sigma = float(np.exp(agent.actor.log_std.detach().numpy()[0]))
    u = mean + sigma * rng.normal(size=t)
    dev = u - mean
    rewards = np.zeros((t, 1, k))
    rewards[:, 0, 0] = -dev  # safety: a lower action is better
    rewards[:, 0, 1] = 2.0 * dev  # overtakes: a higher action is better, twice as strongly
    zeros = np.zeros((t, 1, k))
    return RolloutBuffer(obs=obs, preferences=prefs, pre_actions=u.reshape(t, 1, 1).astype(np.float32),
                         actions=u.reshape(t, 1, 1).astype(np.float32), log_probs=np.zeros((t, 1), np.float32),
                         rewards=rewards, values=zeros, next_values=zeros, terminated=np.ones((t, 1), bool),
                         truncated=np.zeros((t, 1), bool), episodes=[])


@pytest.mark.parametrize("scalarization", ["linear", "stch"])
def test_each_objective_pushes_the_way_its_advantage_points(scalarization: str) -> None:
    cfg = PASTAConfig(hidden_sizes=(8,), critic_head_hidden=0, scalarization=scalarization,
                      normalize_returns=False, action_squashing="clip", initial_action=0.5)
    agent = PASTA(3, 2, [0.05], [1.0], cfg, seed=0)
    rng = np.random.default_rng(0)
    safety = np.where(np.arange(4000) % 2 == 0, 0.9, 0.1)
    bins = objective_push(agent, _buffer(agent, 4000, safety, rng))
    assert [(b.low, b.high) for b in bins] == [(0.0, 0.3), (0.6, 1.0)]  # the empty middle bin is left out
    low, high = bins
    assert low.n == high.n == 2000
    for b in bins:
        assert b.push[0] < 0 < b.push[1]  # safety asks for a lower action, overtakes for a higher one
    # the safety-first preference weighs the downward push more than the pace-first one does
    assert high.attention[0] > low.attention[0]
    assert high.push.sum() < low.push.sum()
    if scalarization == "linear":  # alpha = w: push_j = w_j * c_j * E[dev^2] / sigma^2 = w_j * c_j
        np.testing.assert_allclose(low.push, [-0.1, 2 * 0.9], rtol=0.1)
        np.testing.assert_allclose(high.push, [-0.9, 2 * 0.1], rtol=0.1)


def test_pooling_weights_by_transitions_and_the_table_lists_every_objective() -> None:
    cfg = PASTAConfig(hidden_sizes=(8,), critic_head_hidden=0, scalarization="linear", normalize_returns=False)
    agent = PASTA(3, 2, [0.05], [1.0], cfg, seed=0, objective_names=["safety", "overtakes"])
    rng = np.random.default_rng(1)
    a = objective_push(agent, _buffer(agent, 300, np.full(300, 0.9), rng))
    b = objective_push(agent, _buffer(agent, 100, np.full(100, 0.8), rng))
    (pooled,) = pool_bins([a, b])
    assert pooled.n == 400
    np.testing.assert_allclose(pooled.push, 0.75 * a[0].push + 0.25 * b[0].push)
    table = push_table([pooled], agent.objective_names)
    assert "safety: alpha, push" in table and "overtakes: alpha, push" in table and "| [0.6, 1) | 400 |" in table


def test_a_multi_dimensional_action_is_refused() -> None:
    agent = PASTA(3, 2, [0.05, 0.05], [1.0, 1.0], PASTAConfig(hidden_sizes=(8,), critic_head_hidden=0), seed=0)
    with pytest.raises(ValueError, match="one-dimensional"):
        objective_push(agent, None)


def test_the_push_script_runs_on_a_racing_world(tmp_path, capsys):
    """Smoke: a freshly initialised PASTA with short rollouts, one rollout of the paper world's Laguna Seca."""
    import importlib.util
    from pathlib import Path

    import gymnasium as gym

    import sofar_env  # noqa: F401  (registers the ids)

    env = gym.make("SOfAR-LagunaSeca-v0", reward_mode="vector")
    obs_dim, k = env.observation_space.shape[0], env.unwrapped.reward_space.shape[0]
    env.close()
    cfg = PASTAConfig(hidden_sizes=(8,), critic_head_hidden=0, n_steps=24, batch_size=24, action_squashing="clip",
                      initial_action=0.3, preference_interval=8)
    agent = PASTA(obs_dim, k, [0.05], [1.0], cfg, seed=0,
                  objective_names=["safety", "overtakes", "progress", "barrier_margin", "gamma_smoothness"])
    ckpt = agent.save(tmp_path / "tiny.json")
    spec = importlib.util.spec_from_file_location("pasta_preference_script",
                                                  Path(__file__).parents[2] / "eval" / "pasta_preference.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    mod.main(["push", "--policy", str(ckpt), "--scenario", "paper", "--n-envs", "1", "--rollouts", "1"])
    out = capsys.readouterr().out
    assert "1 rollouts of 1 x 24 steps" in out and "safety: alpha, push" in out and "total push" in out
