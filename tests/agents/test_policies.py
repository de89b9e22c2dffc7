"""The deployable policies: the numpy PASTA policy, fixed gamma, SB3 PPO, the shipped checkpoint."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch

from sofar_agents import PASTA, FixedGammaPolicy, default_policy_path, load_policy
from sofar_agents.policies import PASTAPolicy, SB3Policy
from sofar_agents.wrappers import LinearReward, RescaleGammaAction
from synthetic_envs import SyntheticRace


def _obs(n: int = 32) -> np.ndarray:
    return np.random.default_rng(0).uniform(-1, 1, size=(n, 12)).astype(np.float32)


def test_numpy_policy_matches_the_agent(trained: tuple[PASTA, Path]) -> None:
    agent, path = trained
    obs = _obs()
    expected = agent.predict(obs)
    policy = load_policy(path)
    assert isinstance(policy, PASTAPolicy)
    batch = policy(obs)
    assert batch.shape == (32, 1) and batch.dtype == np.float32
    np.testing.assert_allclose(batch, expected, rtol=0, atol=2e-6)
    single = policy(obs[0])
    assert single.shape == (1,) and 0.05 <= single[0] <= 1.0
    np.testing.assert_allclose(single, expected[0], atol=2e-6)
    # Loading from the .pt path or the bare stem works too.
    np.testing.assert_allclose(load_policy(path.with_suffix(".pt"))(obs[0]), single)
    np.testing.assert_allclose(load_policy(path.with_suffix(""))(obs[0]), single)
    # A preference override changes the cached input.
    other = load_policy(path, preference=[1, 0, 0, 0, 0])
    np.testing.assert_allclose(other(obs), agent.predict(obs, preference=[1, 0, 0, 0, 0]), atol=2e-6)
    with pytest.raises(ValueError, match="non-negative weights"):
        other.set_preference([1, -1, 0, 0, 0])


def test_wrong_format_version(trained: tuple[PASTA, Path], tmp_path: Path) -> None:
    meta = json.loads(trained[1].read_text())
    meta["format_version"] += 1
    meta["weights_file"] = str(trained[1].with_suffix(".pt").resolve())
    (tmp_path / "tampered.json").write_text(json.dumps(meta))
    with pytest.raises(ValueError, match=r"tampered\.json.*format_version"):
        load_policy(tmp_path / "tampered.json")


def test_wrong_obs_dim(trained: tuple[PASTA, Path], tmp_path: Path) -> None:
    meta = json.loads(trained[1].read_text())
    meta["obs_dim"] = 11
    meta["weights_file"] = str(trained[1].with_suffix(".pt").resolve())
    (tmp_path / "tampered.json").write_text(json.dumps(meta))
    with pytest.raises(ValueError, match=r"agent\.pt.*actor input has 17 features.*obs_dim 11"):
        load_policy(tmp_path / "tampered.json")
    with pytest.raises(ValueError, match=r"observations of size 12, not 10"):
        load_policy(trained[1], obs_dim=10)
    with pytest.raises(ValueError, match="observation of shape"):
        load_policy(trained[1])(np.zeros(11, np.float32))


def test_wrong_tensor_shapes(trained: tuple[PASTA, Path], tmp_path: Path) -> None:
    _, path = trained
    state = torch.load(path.with_suffix(".pt"), weights_only=True)
    state["actor"]["mean_net.2.weight"] = torch.zeros(64, 32)
    torch.save(state, tmp_path / "bad.pt")
    meta = json.loads(path.read_text())
    meta["weights_file"] = "bad.pt"
    (tmp_path / "bad.json").write_text(json.dumps(meta))
    with pytest.raises(ValueError, match=r"bad\.pt.*layer 1 expects 32 inputs"):
        load_policy(tmp_path / "bad.json")


def test_missing_files(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError):
        load_policy(tmp_path / "nothing.json")


def test_default_policy_path() -> None:
    try:
        path = default_policy_path()
    except FileNotFoundError as err:
        assert "train/pasta.py" in str(err)
    else:
        assert path.name == "pasta_lagunaseca_sofar17.json"  # trained with the default controller
        assert load_policy(path, obs_dim=12)(np.zeros(12, np.float32)).shape == (1,)


def test_fixed_gamma_policy() -> None:
    policy = FixedGammaPolicy(0.3)
    out = policy(np.zeros(12, np.float32))
    assert out.shape == (1,) and out.dtype == np.float32 and out[0] == pytest.approx(0.3)
    out[0] = 5.0  # callers cannot alter the policy
    assert policy(np.zeros(12))[0] == pytest.approx(0.3)
    assert policy(np.zeros((4, 12))).shape == (4, 1)
    for bad in (0.0, 1.5, float("nan")):
        with pytest.raises(ValueError):
            FixedGammaPolicy(bad)


def test_sb3_policy(tmp_path: Path) -> None:
    from stable_baselines3 import PPO

    torch.set_num_threads(1)
    env = RescaleGammaAction(LinearReward(SyntheticRace(), weights=[1, 1, 0, 0, 0]))
    model = PPO("MlpPolicy", env, n_steps=64, batch_size=32, n_epochs=1, seed=0, device="cpu")
    model.learn(64)
    model.save(tmp_path / "ppo.zip")
    policy = SB3Policy(tmp_path / "ppo.zip")
    obs = _obs(8)
    single = policy(obs[0])
    assert single.shape == (1,) and 0.05 <= single[0] <= 1.0
    action, _ = model.predict(obs[0], deterministic=True)
    assert single[0] == pytest.approx(0.05 + (np.clip(action[0], -1, 1) + 1) / 2 * 0.95, abs=1e-6)
    assert policy(obs).shape == (8, 1)


def test_every_named_policy_ships_and_loads_by_name():
    from sofar_agents.policies import NAMED_POLICIES, named_policy_path

    for name in NAMED_POLICIES:
        assert named_policy_path(name).is_file(), name
        policy = load_policy(name)
        assert policy(np.zeros(policy.obs_dim, np.float32)).shape == (1,)
    with pytest.raises(KeyError, match="morl-dynamic"):
        named_policy_path("morl")


@pytest.mark.parametrize("name", ["morl-dynamic", "morl-dynamic-sofar-4", "morl-interactive-sofar-4",
                                  "morl-dynamic-sofar-6", "morl-interactive-sofar-6", "morl-dynamic-sofar-13",
                                  "morl-interactive-sofar-13", "morl-interactive-sofar-13-sigmoid",
                                  "morl-dynamic-sofar-13-sigmoid", "morl-interactive-sofar-17",
                                  "morl-dynamic-sofar-17", "morl-interactive-2-sofar-17",
                                  "morl-dynamic-2-sofar-17"])
def test_the_shipped_morl_policies_lower_gamma_as_safety_weighs_more(name):
    """The documented direction of the preference input, on fixed states: the mean gamma over a set of
    observations falls as the safety weight grows (overtakes weight 0.9 minus it), and by a margin."""
    from sofar_agents.evaluation.preference_probe import safety_preferences

    policy = load_policy(name)
    obs = np.random.default_rng(0).uniform(-0.5, 0.5, (200, policy.obs_dim)).astype(np.float32)
    means = []
    for w in safety_preferences([0.1, 0.3, 0.5, 0.7, 0.9]):
        policy.set_preference(w)
        means.append(float(np.mean([policy(o)[0] for o in obs])))
    assert all(a >= b for a, b in zip(means, means[1:])), means  # the bound 0.05 may be reached early
    assert means[0] - means[-1] > 0.05, means
