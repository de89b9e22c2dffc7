"""Checkpoint round trips, the numpy policy, error messages and the simple policies."""

from __future__ import annotations

import json
import time
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import torch

from sofar_agents import PASTA, PASTAConfig, FixedGammaPolicy, default_policy_path, load_policy
from sofar_agents.policies import FORMAT_VERSION, PASTAPolicy, SB3Policy
from sofar_agents.wrappers import LinearReward, RescaleGammaAction
from synthetic_envs import OBJECTIVES, SyntheticRace

PREF = [0.31, 0.45, 0.05, 0.04, 0.15]


@pytest.fixture(scope="module")
def trained(tmp_path_factory: pytest.TempPathFactory) -> tuple[PASTA, Path]:
    """A PASTA agent after one small update on the synthetic race, saved to disk."""
    torch.set_num_threads(1)
    venv = gym.vector.SyncVectorEnv([lambda: LinearReward(SyntheticRace())],
                                    autoreset_mode=gym.vector.AutoresetMode.SAME_STEP)
    config = PASTAConfig(n_steps=64, n_epochs=2, hidden_sizes=(64, 64), critic_head_hidden=16, pcgrad=True)
    agent = PASTA(12, 5, [0.05], [1.0], config, preference=PREF, seed=7, objective_names=OBJECTIVES)
    agent.learn(venv, 128)
    venv.close()
    path = agent.save(tmp_path_factory.mktemp("ckpt") / "agent", metadata={"command": "test", "seed": 7})
    return agent, path


def _obs(n: int = 32) -> np.ndarray:
    return np.random.default_rng(0).uniform(-1, 1, size=(n, 12)).astype(np.float32)


def test_save_writes_state_dict_and_json(trained: tuple[PASTA, Path]) -> None:
    agent, path = trained
    assert path.suffix == ".json" and path.with_suffix(".pt").is_file()
    meta = json.loads(path.read_text())
    assert meta["format_version"] == FORMAT_VERSION
    assert meta["obs_dim"] == 12 and meta["n_objectives"] == 5
    assert meta["objective_names"] == list(OBJECTIVES)
    assert meta["action_low"] == [0.05] and meta["action_high"] == [1.0]
    np.testing.assert_allclose(meta["preference"], np.array(PREF) / sum(PREF))
    assert meta["config"]["hidden_sizes"] == [64, 64]
    assert meta["state"]["num_timesteps"] == 128 and meta["state"]["num_updates"] == 2
    assert meta["training"]["command"] == "test" and "code_version" in meta["training"]
    state = torch.load(path.with_suffix(".pt"), weights_only=True)  # tensors only
    assert set(state) >= {"actor", "critic", "optimizer"}


def test_round_trip_gives_identical_actions(trained: tuple[PASTA, Path]) -> None:
    agent, path = trained
    obs = _obs()
    expected = agent.predict(obs)
    loaded = PASTA.load(path)
    np.testing.assert_array_equal(loaded.predict(obs), expected)
    assert loaded.num_timesteps == agent.num_timesteps
    assert loaded.mu_controller.mu == pytest.approx(agent.mu_controller.mu)
    np.testing.assert_allclose(loaded.return_rms.var, agent.return_rms.var)
    assert loaded.objective_names == tuple(OBJECTIVES)

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
    # A preference override changes the cached input.
    other = load_policy(path, preference=[1, 0, 0, 0, 0])
    np.testing.assert_allclose(other(obs), agent.predict(obs, preference=[1, 0, 0, 0, 0]), atol=2e-6)


def test_stochastic_actions_within_bounds_and_log_prob(trained: tuple[PASTA, Path]) -> None:
    agent, _ = trained
    obs = _obs(256)
    a = agent.predict(obs, deterministic=False)
    assert np.all((a >= 0.05) & (a <= 1.0))
    # The density over gamma integrates to one (change of variables included).
    grid = np.linspace(0.05 + 1e-5, 1.0 - 1e-5, 20001)
    dens = np.exp(agent.log_prob(np.repeat(obs[:1], grid.size, axis=0), grid))
    assert np.trapezoid(dens, grid) == pytest.approx(1.0, abs=1e-3)


def test_inference_time(trained: tuple[PASTA, Path]) -> None:
    _, path = trained
    policy = load_policy(path)
    obs = _obs(1)[0]
    for _ in range(200):
        policy(obs)
    n = 2000
    t0 = time.perf_counter()
    for _ in range(n):
        policy(obs)
    per_call = (time.perf_counter() - t0) / n
    # Budget 0.2 ms on an idle core; generous bound for loaded CI machines.
    assert per_call < 1e-3, f"{per_call * 1e3:.3f} ms per call"


def _tamper(path: Path, tmp_path: Path, **changes: object) -> Path:
    meta = json.loads(path.read_text())
    meta.update(changes)
    meta["weights_file"] = str(path.with_suffix(".pt").resolve())
    out = tmp_path / "tampered.json"
    out.write_text(json.dumps(meta))
    return out


def test_wrong_format_version(trained: tuple[PASTA, Path], tmp_path: Path) -> None:
    bad = _tamper(trained[1], tmp_path, format_version=FORMAT_VERSION + 1)
    with pytest.raises(ValueError, match=r"tampered\.json.*format_version"):
        load_policy(bad)
    with pytest.raises(ValueError, match="format_version"):
        PASTA.load(bad)


def test_wrong_obs_dim(trained: tuple[PASTA, Path], tmp_path: Path) -> None:
    bad = _tamper(trained[1], tmp_path, obs_dim=11)
    with pytest.raises(ValueError, match=r"agent\.pt.*actor input has 17 features.*obs_dim 11"):
        load_policy(bad)
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
    with pytest.raises(ValueError, match=r"bad\.pt"):
        PASTA.load(tmp_path / "bad.json")


def test_missing_files(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError):
        load_policy(tmp_path / "nothing.json")


def test_default_policy_path() -> None:
    try:
        path = default_policy_path()
    except FileNotFoundError as err:
        assert "train/pasta.py" in str(err)
    else:
        assert path.name == "pasta_lagunaseca.json"
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


def test_collect_requires_same_step_autoreset() -> None:
    venv = gym.vector.SyncVectorEnv([lambda: LinearReward(SyntheticRace())])  # NEXT_STEP default
    agent = PASTA(12, 5, [0.05], [1.0], PASTAConfig(hidden_sizes=(8,), critic_head_hidden=0))
    with pytest.raises(ValueError, match="SAME_STEP"):
        agent.collect(venv, 4)
    venv.close()


def test_initial_action_sets_the_untrained_deterministic_action():
    from sofar_agents.pasta import PASTA, PASTAConfig

    agent = PASTA(12, 5, [0.05], [1.0], PASTAConfig(initial_action=0.15, hidden_sizes=(16, 16)), seed=0)
    np.testing.assert_allclose(agent.predict(np.zeros((2, 12), np.float32), deterministic=True), 0.15, atol=2e-3)
    with pytest.raises(ValueError, match="inside the action bounds"):
        PASTA(12, 5, [0.05], [1.0], PASTAConfig(initial_action=1.0, hidden_sizes=(16, 16)), seed=0)
