"""A PASTA checkpoint records the configuration hash and the resolved configuration of its training env."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from sofar_agents import PASTA, PASTAConfig
from sofar_agents.pasta.env_reconstruction import sidecar_path, sidecar_record
from sofar_agents.pasta.env_record import training_env_config, training_env_record
from sofar_env.config_hash import config_hash, hash_of_canonical

ROOT = Path(__file__).resolve().parents[2]


def _agent() -> PASTA:
    return PASTA(12, 5, [0.05], [1.0], PASTAConfig(hidden_sizes=(8, 8)), seed=0)


def test_the_checkpoint_json_holds_the_training_env_config(tmp_path) -> None:
    meta = {"env_id": "SOfAR-LagunaSeca-v0", "env_kwargs": {"stack": "paper"}, "decision_interval": 2}
    path = _agent().save(tmp_path / "agent", metadata=meta)
    training = json.loads(path.read_text())["training"]
    cfg = training_env_config(meta)
    assert (cfg.stack.speed_factor, cfg.decision_interval, cfg.reward_mode) == (
        training["env_config"]["stack"]["speed_factor"], 2, "vector")
    assert training["env_config_hash"] == config_hash(cfg) == hash_of_canonical(training["env_config"])
    other = training_env_record({**meta, "env_kwargs": {"stack": "sofar"}})
    assert other["env_config_hash"] != training["env_config_hash"]
    assert PASTA.load(path).metadata["env_config_hash"] == training["env_config_hash"]


def test_no_env_id_no_record_and_an_unknown_env_does_not_stop_a_save(tmp_path) -> None:
    assert training_env_record({}) == {}
    assert training_env_record({"env_id": "NoSuchEnv-v0"}) == {}
    path = _agent().save(tmp_path / "agent", metadata={"env_id": "NoSuchEnv-v0"})
    assert "env_config_hash" not in json.loads(path.read_text())["training"]


def _committed_checkpoints() -> list:
    paths = [*sorted((ROOT / "sofar_agents" / "checkpoints").glob("*.json")),
             *sorted((ROOT / "results").glob("**/*.json"))]
    return [p for p in paths if "weights_file" in json.loads(p.read_text())]


def _training_env(path: Path) -> dict:
    """The checkpoint's own record of its training environment, or else its sidecar's (written by replay)."""
    training = json.loads(path.read_text())["training"]
    if "env_config_hash" in training:
        assert not sidecar_path(path).exists(), path
        return training
    side = json.loads(sidecar_path(path).read_text())
    assert side["checkpoint"] == path.name and side == {**sidecar_record(path), "checkpoint": path.name,
                                                        "policy_id": side["policy_id"]}, path  # its files
    return side


def test_every_committed_checkpoint_carries_its_training_config_hash() -> None:
    paths = _committed_checkpoints()
    assert len(paths) >= 10
    for path in paths:
        record = _training_env(path)
        replayed = record.get("env_config_reconstructed")
        assert record["env_config_hash"] == hash_of_canonical(record["env_config"]), path
        assert PASTA.load(path).metadata["env_config_hash"] == record["env_config_hash"], path
        if replayed is not None:  # recovered by replay: the name it was replayed under still means that config
            last = replayed["stages"][-1]
            meta = {"env_id": last["env_id"], "env_kwargs": last["env_kwargs_now"], "multi_agent": last["multi_agent"]}
            assert last["identical"] and last["env_config_hash"] == record["env_config_hash"], path
            assert training_env_record(meta)["env_config_hash"] == record["env_config_hash"], path


def test_the_reconstructed_environments_still_replay_what_their_training_commits_recorded(training_env_script) -> None:
    """The first decisions of every committed recording under a training commit, replayed by the current code
    under the name the checkpoint's record gives it today, are identical to the bit."""
    script, steps, seen = training_env_script, 25, set()
    for path in _committed_checkpoints():
        record = _training_env(path).get("env_config_reconstructed")
        for stage in (record or {}).get("stages", []):
            if not stage["identical"] or stage["evidence"][0] in seen:
                continue
            seen.add(stage["evidence"][0])
            then = np.load(ROOT / stage["evidence"][0])
            if stage["multi_agent"]:
                now = script.record_race(stage["env_id"], stage["env_kwargs_now"], stage["cars"], 1, steps)
                rows = {"ep0|race": steps * stage["cars"]}
            else:
                now = script.record_single(stage["env_id"], stage["env_kwargs_now"], 1, steps)
                rows = {"ep0|obs": steps + 1, "ep0|reward": steps, "ep0|done": steps}
            assert all(np.array_equal(then[k][:n], now[k][:n]) for k, n in rows.items()), (path, stage["evidence"][0])
    assert len(seen) >= 8
