"""The training wrappers: scalarisation, gamma rescaling, rho per episode."""

from __future__ import annotations

import numpy as np
import pytest

from sofar_agents.wrappers import EVAL_RHOS, LinearReward, RandomRhoReset, RescaleGammaAction
from synthetic_envs import NonConvexBandit, SyntheticRace


def test_linear_reward() -> None:
    env = LinearReward(NonConvexBandit(), weights=[0.25, 0.75])
    env.reset(seed=0)
    _, r, term, _, info = env.step(np.array([0.5], np.float32))
    np.testing.assert_allclose(info["reward_vector"], [0.5, 0.125])
    assert isinstance(r, float) and r == pytest.approx(0.25 * 0.5 + 0.75 * 0.125)
    assert term
    with pytest.raises(ValueError):
        LinearReward(NonConvexBandit(), weights=[1.0, 1.0, 1.0])


def test_rescale_gamma_action() -> None:
    env = RescaleGammaAction(SyntheticRace())
    assert env.action_space.low[0] == -1.0 and env.action_space.high[0] == 1.0
    assert env.action(np.array([-1.0]))[0] == pytest.approx(0.05)
    assert env.action(np.array([1.0]))[0] == pytest.approx(1.0)
    assert env.action(np.array([0.0]))[0] == pytest.approx(0.525)
    assert env.action(np.array([3.0]))[0] == pytest.approx(1.0)
    with pytest.raises(ValueError):
        env.action(np.array([np.nan]))


def test_random_rho_reset_is_seeded_and_respects_options() -> None:
    env = RandomRhoReset(SyntheticRace(), values=EVAL_RHOS)
    rhos = [env.reset(seed=3)[1]["rho"]] + [env.reset()[1]["rho"] for _ in range(30)]
    assert set(rhos) <= set(EVAL_RHOS) and len(set(rhos)) > 1
    again = [env.reset(seed=3)[1]["rho"]] + [env.reset()[1]["rho"] for _ in range(30)]
    assert rhos == again
    assert env.reset(options={"rho": 0.42})[1]["rho"] == pytest.approx(0.42)
    uniform = RandomRhoReset(SyntheticRace(), 0.1, 0.8)
    vals = [uniform.reset(seed=i)[1]["rho"] for i in range(20)]
    assert all(0.1 <= v <= 0.8 for v in vals)
