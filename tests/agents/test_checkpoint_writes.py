"""Checkpoints are written atomically: a save that fails or is interrupted at any point leaves the old pair of
files (loading it gives the old agent), or the new tensor file with the old JSON, which loading refuses with an
error naming both files; never a torn file, never a silent mix. No temporary file is left behind."""

from __future__ import annotations

import json
import os
import shutil
from collections.abc import Callable
from pathlib import Path

import pytest
import torch

from sofar_agents import PASTA
from sofar_agents.policies import load_policy


def _fail_on_call(n: int, real: Callable, exc: type[BaseException] = KeyboardInterrupt) -> Callable:
    """``real``, except that its ``n``-th call raises ``exc`` (after doing nothing)."""
    calls = {"n": 0}

    def fake(*args, **kwargs):
        calls["n"] += 1
        if calls["n"] == n:
            raise exc("injected")
        return real(*args, **kwargs)
    return fake


def _torn_torch_save(obj, f, *args, **kwargs):
    """torch.save that dies half-way: some bytes written, then an interrupt."""
    if hasattr(f, "write"):
        f.write(b"PK\x03\x04 torn")
    else:
        Path(f).write_bytes(b"PK\x03\x04 torn")
    raise KeyboardInterrupt("injected")


# (id, what to patch: (object, attribute, replacement factory), outcome: "old" pair loads, "refused" mismatch)
FAULTS = [
    ("torch-save-torn", (torch, "save", lambda real: _torn_torch_save), "old"),
    ("json-encoding-fails", (json, "dumps", lambda real: _fail_on_call(1, real)), "old"),
    ("pt-fsync-fails", (os, "fsync", lambda real: _fail_on_call(1, real, OSError)), "old"),
    ("json-fsync-fails", (os, "fsync", lambda real: _fail_on_call(2, real, OSError)), "old"),
    ("interrupt-before-the-first-replace", (os, "replace", lambda real: _fail_on_call(1, real)), "old"),
    ("interrupt-between-the-replaces", (os, "replace", lambda real: _fail_on_call(2, real)), "refused"),
]


def _same_agent(a: PASTA, b: PASTA) -> bool:
    return (a.num_timesteps, a.num_updates) == (b.num_timesteps, b.num_updates) and all(
        torch.equal(x, y) for x, y in zip(a.actor.state_dict().values(), b.actor.state_dict().values()))


@pytest.mark.parametrize(("name", "patch", "outcome"), FAULTS, ids=[f[0] for f in FAULTS])
def test_an_interrupted_save_leaves_the_old_pair_or_a_refused_one(trained: tuple[PASTA, Path], tmp_path: Path,
                                                                 monkeypatch: pytest.MonkeyPatch, name: str,
                                                                 patch: tuple, outcome: str) -> None:
    agent, good = trained
    folder = tmp_path / "run"
    folder.mkdir()
    for suffix in (".json", ".pt"):
        shutil.copy(good.with_suffix(suffix), folder / f"agent{suffix}")
    old = PASTA.load(folder / "agent.json")
    newer = PASTA.load(folder / "agent.json")
    newer.num_timesteps += 1000
    with torch.no_grad():
        next(iter(newer.actor.parameters())).add_(1.0)
    target, attribute, make = patch
    monkeypatch.setattr(target, attribute, make(getattr(target, attribute)))
    with pytest.raises((KeyboardInterrupt, OSError)):
        newer.save(folder / "agent")
    monkeypatch.undo()
    assert sorted(p.name for p in folder.iterdir()) == ["agent.json", "agent.pt"]  # no temporary file left
    if outcome == "old":
        assert _same_agent(PASTA.load(folder / "agent.json"), old)
    else:
        for load in (PASTA.load, load_policy):
            with pytest.raises(ValueError) as err:
                load(folder / "agent.json")
            message = str(err.value)
            assert "agent.json" in message and "agent.pt" in message and "weights_sha256" in message, message
    newer.save(folder / "agent")  # the next save repairs the pair
    assert _same_agent(PASTA.load(folder / "agent.json"), newer)


# (id, which tensor file the JSON is paired with, does it load?)
PAIRS = [
    ("own-tensors", "own", True),
    ("tensors-of-another-save", "other", False),
    ("no-digest-in-the-json (older checkpoints)", "legacy", True),
]


@pytest.mark.parametrize(("name", "pairing", "loads"), PAIRS, ids=[p[0] for p in PAIRS])
def test_the_json_and_the_tensor_file_must_belong_together(trained: tuple[PASTA, Path], tmp_path: Path,
                                                           name: str, pairing: str, loads: bool) -> None:
    agent, good = trained
    a = agent.save(tmp_path / "a")
    other = PASTA.load(a)
    with torch.no_grad():
        next(iter(other.actor.parameters())).add_(1.0)
    b = other.save(tmp_path / "b")
    if pairing == "other":
        shutil.copy(b.with_suffix(".pt"), a.with_suffix(".pt"))
    elif pairing == "legacy":
        meta = json.loads(a.read_text())
        del meta["weights_sha256"]
        a.write_text(json.dumps(meta))
    for load in (PASTA.load, load_policy):
        if loads:
            load(a)
        else:
            with pytest.raises(ValueError, match=r"a\.json and .*a\.pt are not one checkpoint: weights_sha256"):
                load(a)


def test_a_saved_pair_has_the_mode_of_a_new_file(trained: tuple[PASTA, Path], tmp_path: Path) -> None:
    """Both files of a checkpoint are readable as any new file is (0666 less the umask), not mkstemp's 0600."""
    agent, _ = trained
    old = os.umask(0o022)
    try:
        json_path = agent.save(tmp_path / "agent")
    finally:
        os.umask(old)
    assert {p.stat().st_mode & 0o777 for p in (json_path, json_path.with_suffix(".pt"))} == {0o644}
