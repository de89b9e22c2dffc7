"""The sigmoid reaching past the bounds, clipped (``action_squashing="sigmoid-clip"``): each bound at a finite
pre-activation, the sigmoid between them, a censored likelihood, bad margins (training, checkpoints and the numpy
policy: ``test_pasta_clip_action.py``)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
import torch

from sofar_agents import PASTA, PASTAConfig, load_policy
from sofar_agents.policies import PASTAPolicy
from sofar_agents.pasta.distribution import SigmoidClipSquash, make_squash

LOW, HIGH = np.array([0.05], np.float32), np.array([1.0], np.float32)


def _obs(n: int = 16) -> np.ndarray:
    return np.random.default_rng(1).uniform(-1, 1, size=(n, 12)).astype(np.float32)


def test_the_bounds_are_reached_at_a_finite_pre_activation_and_between_them_it_is_a_sigmoid() -> None:
    sq = make_squash("sigmoid-clip", LOW, HIGH, 0.05)
    assert isinstance(sq, SigmoidClipSquash)
    # the sigmoid spans [0.05 - 0.0475, 1 + 0.0475]: the lower bound at logit(0.0475 / 1.045)
    u_low = math.log(0.0475 / 1.045) - math.log1p(-0.0475 / 1.045)
    assert float(sq.u_low) == pytest.approx(u_low, abs=1e-4) and float(sq.u_high) == pytest.approx(-u_low, abs=1e-4)
    u = torch.tensor([[-20.0], [u_low - 0.01], [-1.0], [0.0], [2.0], [-u_low + 0.01], [20.0]])
    a = sq(u).numpy().ravel()
    assert a[0] == a[1] == np.float32(0.05) and a[-1] == a[-2] == np.float32(1.0)
    inside = 0.0025 + 1.045 / (1.0 + np.exp(-u.numpy().ravel()[2:5]))
    np.testing.assert_allclose(a[2:5], inside, rtol=1e-6)
    assert np.all(np.diff(a) >= 0)
    torch.testing.assert_close(sq.initial_bias(np.array([0.525], np.float32)), np.zeros(1, np.float32), atol=1e-6,
                               rtol=0, check_dtype=False)


def test_censored_likelihood_is_a_probability_distribution() -> None:
    sq = SigmoidClipSquash(LOW, HIGH, 0.05)
    mean, log_std = torch.tensor([[-2.5]]), torch.tensor([0.0])
    normal = torch.distributions.Normal(0.0, 1.0)
    p_low = float(torch.exp(sq.action_log_prob(torch.tensor([[0.05]]), mean, log_std)))
    assert p_low == pytest.approx(float(normal.cdf(sq.u_low + 2.5)), rel=1e-5)  # P(u <= u_low)
    p_high = float(torch.exp(sq.action_log_prob(torch.tensor([[1.0]]), mean, log_std)))
    assert p_high == pytest.approx(float(1.0 - normal.cdf(sq.u_high + 2.5)), rel=1e-3)
    grid = torch.linspace(0.05, 1.0, 200001)[1:-1].reshape(-1, 1)
    dens = torch.exp(sq.action_log_prob(grid, mean.expand_as(grid), log_std)).numpy().ravel()
    assert np.trapezoid(dens, grid.numpy().ravel()) + p_low + p_high == pytest.approx(1.0, abs=1e-4)


def test_a_mean_past_the_floor_gives_exactly_the_floor_where_a_sigmoid_gives_more() -> None:
    for squashing, floor_exact in (("sigmoid-clip", True), ("sigmoid", False)):
        agent = PASTA(12, 5, LOW, HIGH, PASTAConfig(action_squashing=squashing, hidden_sizes=(16, 16)), seed=0)
        with torch.no_grad():
            agent.actor.mean_net[-1].weight.zero_()
            agent.actor.mean_net[-1].bias.fill_(-3.2)
        gamma = agent.predict(_obs())
        assert np.all(gamma == np.float32(0.05)) == floor_exact
        assert np.all(gamma < 0.1)


@pytest.mark.parametrize("margin", [0.0, -0.1, 1.5, float("nan"), "0.1", True])
def test_a_bad_margin_is_refused_by_the_config_and_by_a_checkpoint(margin, tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="squash_margin"):
        PASTAConfig(action_squashing="sigmoid-clip", squash_margin=margin)
    agent = PASTA(12, 5, LOW, HIGH, PASTAConfig(action_squashing="sigmoid-clip", hidden_sizes=(8,)), seed=0)
    path = agent.save(tmp_path / "sc", metadata={"command": "test"})
    meta = json.loads(path.read_text())
    meta["config"]["squash_margin"] = margin
    meta["weights_file"] = str(path.with_suffix(".pt").resolve())
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(meta))
    with pytest.raises(ValueError, match=r"bad\.json.*squash_margin"):
        load_policy(bad)
    with pytest.raises(ValueError, match="margin must lie in"):
        PASTAPolicy([(np.zeros((4, 17), np.float32), np.zeros(4, np.float32)),
                     (np.zeros((1, 4), np.float32), np.zeros(1, np.float32))], 12, [1, 1, 1, 1, 1], LOW, HIGH,
                    squashing="sigmoid-clip", margin=margin)
