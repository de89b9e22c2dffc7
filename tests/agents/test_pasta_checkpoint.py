"""The checkpoint format: what PASTA.save writes, PASTA.load round trips and format errors."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from sofar_agents import PASTA
from sofar_agents.pasta.checkpoint import (
    FORMAT_VERSION,
    checkpoint_paths,
    read_actor_layers,
    read_checkpoint_metadata,
    read_tensors,
)
from synthetic_envs import OBJECTIVES, PREF


def _obs(n: int = 32) -> np.ndarray:
    return np.random.default_rng(0).uniform(-1, 1, size=(n, 12)).astype(np.float32)


def _tamper(path: Path, tmp_path: Path, **changes: object) -> Path:
    meta = json.loads(path.read_text())
    meta.update(changes)
    meta["weights_file"] = str(path.with_suffix(".pt").resolve())
    out = tmp_path / "tampered.json"
    out.write_text(json.dumps(meta))
    return out


def test_checkpoint_paths() -> None:
    for given in ("run/agent", "run/agent.json", "run/agent.pt"):
        assert checkpoint_paths(given) == (Path("run/agent.json"), Path("run/agent.pt"))


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
    assert set(state) >= {"actor", "critic", "optimizer", "return_rms_mean", "utopia"}


def test_round_trip_restores_the_agent(trained: tuple[PASTA, Path]) -> None:
    agent, path = trained
    obs = _obs()
    loaded = PASTA.load(path)
    np.testing.assert_array_equal(loaded.predict(obs), agent.predict(obs))
    assert loaded.num_timesteps == agent.num_timesteps and loaded.num_updates == agent.num_updates
    assert loaded.mu_controller.mu == pytest.approx(agent.mu_controller.mu)
    np.testing.assert_allclose(loaded.return_rms.var, agent.return_rms.var)
    np.testing.assert_array_equal(loaded.utopia, agent.utopia)
    assert loaded.objective_names == tuple(OBJECTIVES)
    assert loaded.config == agent.config
    for a, b in zip(loaded.critic.parameters(), agent.critic.parameters()):
        torch.testing.assert_close(a, b, rtol=0, atol=0)


def test_read_actor_layers_matches_the_actor(trained: tuple[PASTA, Path]) -> None:
    agent, path = trained
    meta, _, pt_path = read_checkpoint_metadata(path)
    layers = read_actor_layers(meta, pt_path)
    assert [w.shape for w, _ in layers] == [(64, 17), (64, 64), (1, 64)]
    np.testing.assert_array_equal(layers[0][0], agent.actor.mean_net[0].weight.detach().numpy())


def test_wrong_format_version(trained: tuple[PASTA, Path], tmp_path: Path) -> None:
    bad = _tamper(trained[1], tmp_path, format_version=FORMAT_VERSION + 1)
    with pytest.raises(ValueError, match=r"tampered\.json.*format_version"):
        read_checkpoint_metadata(bad)
    with pytest.raises(ValueError, match="format_version"):
        PASTA.load(bad)


def test_inconsistent_metadata(trained: tuple[PASTA, Path], tmp_path: Path) -> None:
    with pytest.raises(ValueError, match=r"preference has 2 entries for 5 objectives"):
        read_checkpoint_metadata(_tamper(trained[1], tmp_path, preference=[0.5, 0.5]))
    with pytest.raises(ValueError, match=r"missing keys \['config'\]"):
        meta = json.loads(trained[1].read_text())
        del meta["config"]
        (tmp_path / "noconfig.json").write_text(json.dumps(meta))
        read_checkpoint_metadata(tmp_path / "noconfig.json")


def test_wrong_tensor_shapes(trained: tuple[PASTA, Path], tmp_path: Path) -> None:
    _, path = trained
    state = torch.load(path.with_suffix(".pt"), weights_only=True)
    state["actor"]["mean_net.2.weight"] = torch.zeros(64, 32)
    torch.save(state, tmp_path / "bad.pt")
    meta = json.loads(path.read_text())
    meta["weights_file"] = "bad.pt"
    (tmp_path / "bad.json").write_text(json.dumps(meta))
    with pytest.raises(ValueError, match=r"bad\.pt.*layer 1 expects 32 inputs"):
        PASTA.load(tmp_path / "bad.json")


def test_unreadable_tensor_file(tmp_path: Path) -> None:
    (tmp_path / "junk.pt").write_bytes(b"not a torch file")
    with pytest.raises(ValueError, match=r"junk\.pt: cannot read"):
        read_tensors(tmp_path / "junk.pt")
    torch.save({"critic": {}}, tmp_path / "noactor.pt")
    with pytest.raises(ValueError, match=r"noactor\.pt: expected a dict with an 'actor'"):
        read_tensors(tmp_path / "noactor.pt")


def test_missing_files(trained: tuple[PASTA, Path], tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match="metadata"):
        read_checkpoint_metadata(tmp_path / "nothing.json")
    meta = json.loads(trained[1].read_text())
    meta["weights_file"] = "gone.pt"
    (tmp_path / "orphan.json").write_text(json.dumps(meta))
    with pytest.raises(FileNotFoundError, match=r"gone\.pt"):
        PASTA.load(tmp_path / "orphan.json")


def test_reading_a_checkpoint_does_not_import_torch(trained: tuple[PASTA, Path]) -> None:
    code = ("import sys; from sofar_agents.pasta.checkpoint import read_checkpoint_metadata; "
            f"read_checkpoint_metadata({str(trained[1])!r}); import sofar_agents.policies; "
            "print('torch' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "False"

