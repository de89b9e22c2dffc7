"""The sigmoid in log units (``action_squashing="log-sigmoid"``): ``a = low * (high / low) ** sigmoid(u)``, a
bijection whose density integrates to one, resolution near the lower bound, and the torch agent, its checkpoint
and the numpy policy agreeing."""

from __future__ import annotations

import json
import math
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import torch

from sofar_agents import PASTA, PASTAConfig, load_policy
from sofar_agents.policies import PASTAPolicy
from sofar_agents.pasta.distribution import LogSigmoidSquash, make_squash
from sofar_agents.wrappers import LinearReward
from synthetic_envs import SyntheticRace

LOW, HIGH = np.array([0.05], np.float32), np.array([1.0], np.float32)


def _obs(n: int = 16) -> np.ndarray:
    return np.random.default_rng(1).uniform(-1, 1, size=(n, 12)).astype(np.float32)


def test_the_map_is_geometric_between_the_bounds_and_inverts() -> None:
    sq = make_squash("log-sigmoid", LOW, HIGH)
    assert isinstance(sq, LogSigmoidSquash)
    u = torch.tensor([[-30.0], [-1.9], [0.0], [1.0], [30.0]])
    a = sq(u).numpy().ravel()
    assert a[0] == pytest.approx(0.05, rel=1e-6) and a[-1] == pytest.approx(1.0, rel=1e-6)
    assert a[2] == pytest.approx(math.sqrt(0.05), rel=1e-6)  # sigmoid 1/2: the geometric mean of the bounds
    assert a[1] == pytest.approx(0.05 * 20.0 ** (1.0 / (1.0 + math.exp(1.9))), rel=1e-6)
    assert np.all(np.diff(a) > 0)
    inner = torch.tensor([[-4.0], [-1.9], [0.3], [2.5]])
    torch.testing.assert_close(sq.inverse(sq(inner)), inner, atol=2e-4, rtol=0)
    torch.testing.assert_close(torch.as_tensor(sq.initial_bias(np.array([0.15], np.float32)), dtype=torch.float32),
                               sq.inverse(torch.tensor([0.15])), atol=1e-5, rtol=0)
    # near the lower bound a unit of u moves gamma by far less than the plain sigmoid's share of the range
    plain = make_squash("sigmoid", LOW, HIGH)
    assert float(plain.inverse(torch.tensor([0.07]))) < -3.7 < -2.2 < float(sq.inverse(torch.tensor([0.07])))


def test_log_det_jacobian_is_the_derivative_and_the_density_integrates_to_one() -> None:
    sq = LogSigmoidSquash(LOW, HIGH)
    u = torch.linspace(-6.0, 6.0, 25, dtype=torch.float64).reshape(-1, 1)  # float64 through the float32 bounds
    eps = 1e-6
    numeric = (sq(u + eps) - sq(u - eps)) / (2 * eps)
    np.testing.assert_allclose(torch.exp(sq.log_abs_det_jacobian(u)).numpy(), numeric.numpy().ravel(), rtol=1e-6)
    mean, log_std = torch.tensor([[-1.5]]), torch.tensor([0.0])
    grid = torch.exp(torch.linspace(math.log(0.05), 0.0, 200001))[1:-1].reshape(-1, 1)
    dens = torch.exp(sq.action_log_prob(grid, mean.expand_as(grid), log_std)).double().numpy().ravel()
    assert np.trapezoid(dens, grid.double().numpy().ravel()) == pytest.approx(1.0, abs=2e-3)


@pytest.mark.parametrize("low", [0.0, -0.1])
def test_a_lower_bound_not_above_zero_is_refused(low: float) -> None:
    with pytest.raises(ValueError, match="0 < low < high"):
        LogSigmoidSquash(np.array([low], np.float32), HIGH)
    layers = [(np.zeros((4, 17), np.float32), np.zeros(4, np.float32)),
              (np.zeros((1, 4), np.float32), np.zeros(1, np.float32))]
    with pytest.raises(ValueError, match="action_low > 0"):
        PASTAPolicy(layers, 12, [1, 1, 1, 1, 1], [low], HIGH, squashing="log-sigmoid")


def test_a_log_sigmoid_agent_starts_where_asked_trains_saves_and_deploys(tmp_path: Path) -> None:
    torch.set_num_threads(1)
    cfg = PASTAConfig(action_squashing="log-sigmoid", initial_action=0.15, log_std_init=0.0, n_steps=32, n_epochs=2,
                      hidden_sizes=(16,), critic_head_hidden=0)
    agent = PASTA(12, 5, LOW, HIGH, cfg, seed=3)
    np.testing.assert_allclose(agent.predict(np.zeros((2, 12), np.float32)), 0.15, atol=5e-3)
    venv = gym.vector.SyncVectorEnv([lambda: LinearReward(SyntheticRace()) for _ in range(2)],
                                    autoreset_mode=gym.vector.AutoresetMode.SAME_STEP)
    buf = agent.collect(venv, 32)
    venv.close()
    assert np.all((buf.actions > 0.05) & (buf.actions < 1.0))
    log = agent.update(buf)
    assert np.isfinite(log["policy_loss"]) and np.isfinite(log["entropy"])
    path = agent.save(tmp_path / "agent", metadata={"command": "test"})
    meta = json.loads(path.read_text())
    assert meta["action_squashing"] == "log-sigmoid" == meta["config"]["action_squashing"]
    np.testing.assert_array_equal(PASTA.load(path).predict(_obs()), agent.predict(_obs()))
    policy = load_policy(path)
    assert policy.squashing == "log-sigmoid"
    np.testing.assert_allclose(policy(_obs()), agent.predict(_obs()), rtol=1e-5)
