"""A PASTA checkpoint records the configuration hash and the resolved configuration of its training env."""

from __future__ import annotations

import json

from sofar_agents import PASTA, PASTAConfig
from sofar_agents.pasta.env_record import training_env_config, training_env_record
from sofar_env.config_hash import config_hash, hash_of_canonical


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
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    paths = [*sorted((root / "sofar_agents" / "checkpoints").glob("*.json")),
             *sorted((root / "results").glob("**/*.json"))]
    return [p for p in paths if "weights_file" in json.loads(p.read_text())]


TRAINED_BEFORE_THE_RECORD = {
    "pasta_lagunaseca.json", "pasta_lagunaseca_interactive.json", "pasta_lagunaseca_paper.json", "pasta_dynamic.json",
    "pasta_dynamic_low.json", "pasta_midstart.json", "selfplay_lagunaseca.json", "pasta_midstart_800k.json",
    "pasta_paper_800k.json", "pasta_paper_seed72.json",
}
"""Committed checkpoints trained before checkpoints recorded their training environment's configuration: what
that configuration was is known by its command (``training.command``), not by value, so they carry no hash (the
tables they made carry the hash of the controller they were evaluated with). Re-trained, they gain one."""


def test_every_committed_checkpoint_carries_its_training_config_hash_or_predates_it() -> None:
    paths = _committed_checkpoints()
    assert len(paths) >= 10
    for path in paths:
        training = json.loads(path.read_text())["training"]
        if path.name in TRAINED_BEFORE_THE_RECORD:
            assert "env_config_hash" not in training and training.get("command"), path
        else:
            assert training["env_config_hash"] == hash_of_canonical(training["env_config"]), path
    assert TRAINED_BEFORE_THE_RECORD <= {p.name for p in paths}
