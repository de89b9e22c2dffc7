"""The clipped-Gaussian action (``action_squashing="clip"``): censored likelihood, bounds reached
exactly, training, checkpoints and the numpy deployment policy (training and deployment also for the other censored
squashing, ``"sigmoid-clip"``: ``test_pasta_sigmoid_clip.py``)."""

from __future__ import annotations

import json
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import torch

from sofar_agents import PASTA, PASTAConfig, load_policy
from sofar_agents.pasta.distribution import ClipSquash, make_squash
from sofar_agents.wrappers import LinearReward
from synthetic_envs import SyntheticRace

LOW, HIGH = np.array([0.05], np.float32), np.array([1.0], np.float32)


def _obs(n: int = 16) -> np.ndarray:
    return np.random.default_rng(1).uniform(-1, 1, size=(n, 12)).astype(np.float32)


def test_clip_is_the_identity_inside_and_the_bound_outside() -> None:
    sq = ClipSquash(LOW, HIGH)
    u = torch.tensor([[-0.3], [0.05], [0.4], [1.0], [2.5]])
    torch.testing.assert_close(sq(u), torch.tensor([[0.05], [0.05], [0.4], [1.0], [1.0]]))
    assert torch.all(sq.log_abs_det_jacobian(u) == 0)
    with pytest.raises(ValueError, match="unknown action squashing 'tanh'"):
        make_squash("tanh", LOW, HIGH)


def test_censored_likelihood_is_a_probability_distribution() -> None:
    sq = ClipSquash(LOW, HIGH)
    mean, log_std = torch.tensor([[0.1]]), torch.tensor([np.log(0.2)], dtype=torch.float32)
    # mass at the lower bound = P(u <= 0.05) for u ~ N(0.1, 0.2^2) = Phi(-0.25)
    p_low = float(torch.exp(sq.action_log_prob(torch.tensor([[0.05]]), mean, log_std)))
    assert p_low == pytest.approx(0.401294, abs=1e-5)
    p_high = float(torch.exp(sq.action_log_prob(torch.tensor([[1.0]]), mean, log_std)))
    assert p_high == pytest.approx(3.3977e-6, rel=1e-3)  # 1 - Phi(4.5)
    grid = torch.linspace(0.05, 1.0, 20001)[1:-1].reshape(-1, 1)
    dens = torch.exp(sq.action_log_prob(grid, mean.expand_as(grid), log_std)).numpy().ravel()
    assert np.trapezoid(dens, grid.numpy().ravel()) + p_low + p_high == pytest.approx(1.0, abs=1e-4)


def test_untrained_agent_starts_at_the_initial_action_and_reaches_the_bound() -> None:
    cfg = PASTAConfig(action_squashing="clip", initial_action=0.3, log_std_init=-2.0, hidden_sizes=(16, 16))
    agent = PASTA(12, 5, LOW, HIGH, cfg, seed=0)
    np.testing.assert_allclose(agent.predict(np.zeros((2, 12), np.float32)), 0.3, atol=5e-3)
    # a mean beyond the bound gives exactly the bound as the deterministic action
    with torch.no_grad():
        agent.actor.mean_net[-1].bias.fill_(-0.4)
    np.testing.assert_array_equal(agent.predict(_obs()), np.float32(0.05))
    stochastic = agent.predict(_obs(256), deterministic=False)
    assert np.all((stochastic >= 0.05) & (stochastic <= 1.0)) and np.mean(stochastic == np.float32(0.05)) > 0.99


@pytest.mark.parametrize("squashing, extra", [("clip", dict(log_std_init=-2.3)),
                                               ("sigmoid-clip", dict(log_std_init=0.0, squash_margin=0.1))])
def test_a_censored_agent_trains_saves_and_deploys(squashing: str, extra: dict, tmp_path: Path) -> None:
    torch.set_num_threads(1)
    venv = gym.vector.SyncVectorEnv([lambda: LinearReward(SyntheticRace()) for _ in range(2)],
                                    autoreset_mode=gym.vector.AutoresetMode.SAME_STEP)
    cfg = PASTAConfig(action_squashing=squashing, initial_action=0.1, n_steps=32, n_epochs=2, hidden_sizes=(16,),
                      critic_head_hidden=0, **extra)
    agent = PASTA(12, 5, LOW, HIGH, cfg, seed=3)
    buf = agent.collect(venv, 32)
    venv.close()
    assert np.any(buf.actions == np.float32(0.05)) and np.any(buf.actions > 0.05)  # censored samples occur
    log = agent.update(buf)
    assert np.isfinite(log["policy_loss"]) and np.isfinite(log["entropy"])
    path = agent.save(tmp_path / "agent", metadata={"command": "test"})
    meta = json.loads(path.read_text())
    assert meta["action_squashing"] == squashing and meta["config"]["action_squashing"] == squashing
    assert meta["config"]["squash_margin"] == cfg.squash_margin
    loaded = PASTA.load(path)
    np.testing.assert_array_equal(loaded.predict(_obs()), agent.predict(_obs()))
    policy = load_policy(path)
    assert policy.squashing == squashing
    np.testing.assert_allclose(policy(_obs()), agent.predict(_obs()), atol=1e-6)
    with torch.no_grad():  # a mean far past the floor: the numpy policy gives exactly the floor too
        agent.actor.mean_net[-1].bias.fill_(-30.0)
    np.testing.assert_array_equal(load_policy(agent.save(tmp_path / "floor", metadata={}))(_obs()), np.float32(0.05))


def test_checkpoint_squashing_must_agree_with_its_config(tmp_path: Path) -> None:
    agent = PASTA(12, 5, LOW, HIGH, PASTAConfig(action_squashing="clip", hidden_sizes=(8,)), seed=0)
    path = agent.save(tmp_path / "clip", metadata={"command": "test"})
    meta = json.loads(path.read_text())
    meta["action_squashing"] = "sigmoid"
    meta["weights_file"] = str(path.with_suffix(".pt").resolve())
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(meta))
    with pytest.raises(ValueError, match=r"bad\.json: action_squashing 'sigmoid' disagrees with the config's 'clip'"):
        PASTA.load(bad)
