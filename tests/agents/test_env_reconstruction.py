"""A checkpoint older than the training-environment record gains it only from replays identical to the bit."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from sofar_agents import PASTA, PASTAConfig
from sofar_agents.evaluation.files import content_id
from sofar_agents.pasta.env_reconstruction import (Replay, backfill_checkpoint, recorded_commits, sidecar_path,
                                                   sidecar_record)
from sofar_agents.pasta.env_record import training_env_record

ENV_KWARGS = {"stack": "paper"}


@pytest.fixture(scope="module")
def recordings(tmp_path_factory, training_env_script):
    """Two recordings of the same seeded steps, and one whose second step differs."""
    import sofar_env

    folder = tmp_path_factory.mktemp("replays")
    data = training_env_script.record_single("SOfAR-LagunaSeca-v0", ENV_KWARGS, episodes=1, steps=4)
    meta = {"env_id": "SOfAR-LagunaSeca-v0", "env_kwargs": ENV_KWARGS, "multi_agent": False, "cars": None,
            "episodes": 1, "steps": 4, "sofar_env": str(Path(sofar_env.__file__).parent)}
    changed = data["ep0|obs"].copy()
    changed[2, 0] += 1.0
    paths = {}
    for name, commit, arrays in [("then", "2ab06614fef0dc5dae83142db850cc5ecf253e15", data), ("now", "HEAD", data),
                                 ("other", "2ab06614fef0dc5dae83142db850cc5ecf253e15", {**data, "ep0|obs": changed})]:
        paths[name] = folder / f"{name}.npz"
        np.savez(paths[name], meta=np.array(json.dumps({**meta, "commit": commit})), **arrays)
    return paths


def _checkpoint(tmp_path, **training) -> Path:
    agent = PASTA(12, 5, [0.05], [1.0], PASTAConfig(hidden_sizes=(8, 8)), seed=0)
    path = agent.save(tmp_path / "agent")
    meta = json.loads(path.read_text())
    meta["training"] = {"command": "python train/pasta.py --stack paper", "env_id": "SOfAR-LagunaSeca-v0",
                        "env_kwargs": ENV_KWARGS, "multi_agent": False,
                        "code_commit": "2ab06614fef0dc5dae83142db850cc5ecf253e15+dirty", **training}
    path.write_text(json.dumps(meta, indent=2))
    return path


def test_identical_replays_write_the_hash_of_the_configuration_named_today(tmp_path, recordings) -> None:
    path = _checkpoint(tmp_path)
    files = path.read_bytes(), path.with_suffix(".pt").read_bytes()
    replay = Replay.load(recordings["then"], recordings["now"])
    assert replay.identical and replay.arrays == 3 and replay.decisions == 4
    side = backfill_checkpoint(path, [replay], ["stage 0: in no commit"], command="cmd")
    assert (path.read_bytes(), path.with_suffix(".pt").read_bytes()) == files  # the policy id stays
    written = json.loads(sidecar_path(path).read_text())
    assert written == side and sidecar_path(path).name == "agent.training_env.json"
    assert written["policy_id"] == content_id(path, path.with_suffix(".pt"))
    expected = training_env_record({"env_id": "SOfAR-LagunaSeca-v0", "env_kwargs": ENV_KWARGS})
    assert written["env_config_hash"] == expected["env_config_hash"]
    assert written["env_config"] == expected["env_config"]
    stage, = written["env_config_reconstructed"]["stages"]
    assert stage["identical"] and stage["recorded_as"].endswith("+dirty") and stage["env_config_hash"]
    assert written["env_config_reconstructed"]["unverified"] == ["stage 0: in no commit"]
    metadata = PASTA.load(path).metadata
    assert metadata["env_config_hash"] == expected["env_config_hash"] and metadata["command"].startswith("python")


def test_a_replay_that_differs_is_recorded_without_a_hash(tmp_path, recordings) -> None:
    path = _checkpoint(tmp_path)
    replay = Replay.load(recordings["other"], recordings["now"])
    assert not replay.identical and replay.first_difference == "ep0|obs: row 2 of 5"
    side = backfill_checkpoint(path, [replay], [], command="cmd")
    assert "env_config_hash" not in side and "env_config" not in side
    assert side["env_config_reconstructed"]["stages"][0]["env_config_hash"] is None
    assert "env_config_hash" not in PASTA.load(path).metadata


def test_a_sidecar_of_other_files_is_ignored(tmp_path, recordings, caplog) -> None:
    path = _checkpoint(tmp_path)
    backfill_checkpoint(path, [Replay.load(recordings["then"], recordings["now"])], [], command="cmd")
    assert sidecar_record(path)["env_config_hash"]
    meta = json.loads(path.read_text())
    meta["preference"] = [0.5, 0.2, 0.1, 0.1, 0.1]  # the checkpoint changed after its sidecar was written
    path.write_text(json.dumps(meta, indent=2))
    assert sidecar_record(path) == {} and "belongs to other files" in caplog.text
    assert "env_config_hash" not in PASTA.load(path).metadata


@pytest.mark.parametrize("case, message", [
    ("commit the checkpoint does not record", "of no commit the checkpoint records"),
    ("another environment", "not of the checkpoint's own environment"),
    ("recorded under other code", "not this code"),
    ("already recorded", "records its training environment already"),
    ("no replay", "no replay given"),
])
def test_a_wrong_backfill_raises_and_leaves_the_checkpoint_as_it_was(tmp_path, recordings, case, message) -> None:
    training = {"code_commit": "0123456789abcdef"} if case.startswith("commit") else {}
    if case == "another environment":
        training["env_kwargs"] = {"stack": "sofar-1"}
    if case == "already recorded":
        training["env_config_hash"] = "abc"
    path = _checkpoint(tmp_path, **training)
    before = path.read_bytes()
    sidecar_path(path).write_text("{}")
    replay = Replay.load(recordings["then"], recordings["now"])
    if case == "recorded under other code":
        replay = Replay({**replay.then}, {**replay.now, "sofar_env": str(tmp_path)}, replay.arrays, replay.decisions,
                        None)
    with pytest.raises(ValueError, match=message):
        backfill_checkpoint(path, [] if case == "no replay" else [replay], [], command="cmd")
    assert path.read_bytes() == before and sidecar_path(path).read_text() == "{}"


def test_recordings_of_different_environments_are_not_a_pair(tmp_path, recordings) -> None:
    other = tmp_path / "other_env.npz"
    data = dict(np.load(recordings["now"]))
    meta = json.loads(str(data.pop("meta")))
    np.savez(other, meta=np.array(json.dumps({**meta, "env_id": "SOfAR-Monza-v0"})), **data)
    with pytest.raises(ValueError, match="different env_id"):
        Replay.load(recordings["then"], other)


def test_recorded_commits_lists_the_run_and_its_stages_once() -> None:
    training = {"code_commit": "abc1234", "history": [{"code_commit": "def5678 (+ uncommitted work)"},
                                                      {"code_commit": "abc1234"}, {"steps": 3}]}
    assert recorded_commits(training) == ["abc1234", "def5678 (+ uncommitted work)"]


def test_the_script_records_and_backfills_a_checkpoint(tmp_path, training_env_script) -> None:
    import sofar_env

    script = training_env_script
    commit = script._code_of(sofar_env)["commit"].removesuffix("+dirty")
    if commit == "unknown":
        pytest.skip("not a git checkout")
    path = _checkpoint(tmp_path, code_commit=commit)
    for name in ("then", "now"):
        assert script.main(["record", "--checkpoint", str(path), "--out", str(tmp_path / f"{name}.npz"),
                            "--episodes", "1", "--steps", "3"]) == 0
    assert script.main(["backfill", str(path), "--evidence", str(tmp_path / "then.npz"), str(tmp_path / "now.npz"),
                        "--note", "a note"]) == 0
    side = json.loads(sidecar_path(path).read_text())
    assert side["env_config_hash"] == training_env_record(
        {"env_id": "SOfAR-LagunaSeca-v0", "env_kwargs": ENV_KWARGS})["env_config_hash"]
    record = side["env_config_reconstructed"]
    assert record["note"] == "a note" and record["stages"][0]["decisions"] == 3
    assert record["command"].startswith("python eval/training_env.py backfill ")
    with pytest.raises(SystemExit):
        script.main(["backfill", str(path), "--evidence", str(tmp_path / "then.npz")])
