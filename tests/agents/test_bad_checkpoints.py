"""Bad checkpoints: every malformed file gives a ValueError naming the file and the field.

Each case is ``(id, how to spoil a good checkpoint, words the message must contain)``;
both :func:`sofar_agents.policies.load_policy` and :meth:`sofar_agents.PASTA.load`
are run on the spoiled files.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from pathlib import Path

import pytest
import torch

from sofar_agents import PASTA
from sofar_agents.policies import load_policy

Spoil = Callable[[dict, dict], None]
"""Edits ``(metadata, tensors)`` of a good checkpoint in place."""


def _meta(**changes: object) -> Spoil:
    return lambda meta, state: meta.update(changes)


def _drop(key: str) -> Spoil:
    return lambda meta, state: meta.pop(key)


def _actor_tensor(key: str, value: float) -> Spoil:
    def spoil(meta: dict, state: dict) -> None:
        state["actor"][key] = state["actor"][key].clone()
        state["actor"][key].view(-1)[0] = value
    return spoil


def _critic_nan(meta: dict, state: dict) -> None:
    key = next(iter(state["critic"]))
    state["critic"][key] = torch.full_like(state["critic"][key], math.nan)


def _drop_tensor(key: str) -> Spoil:
    return lambda meta, state: state.pop(key)


# (id, spoil, words in the message, also a load_policy error?)
META_CASES = [
    ("nan-preference", _meta(preference=[math.nan, 1, 1, 1, 1]), ["preference", "finite"], True),
    ("inf-preference", _meta(preference=[math.inf, 1, 1, 1, 1]), ["preference", "finite"], True),
    ("negative-preference", _meta(preference=[-1, 1, 1, 1, 1]), ["preference", "non-negative"], True),
    ("zero-preference", _meta(preference=[0, 0, 0, 0, 0]), ["preference", "positive"], True),
    ("short-preference", _meta(preference=[0.5, 0.5]), ["preference", "2 entries"], True),
    ("string-preference", _meta(preference="uniform"), ["preference"], True),
    ("inverted-bounds", _meta(action_low=[1.0], action_high=[0.05]), ["action_low", "action_high"], True),
    ("equal-bounds", _meta(action_low=[0.5], action_high=[0.5]), ["action_low", "action_high"], True),
    ("nan-bound", _meta(action_low=[math.nan]), ["action_low", "finite"], True),
    ("inf-bound", _meta(action_high=[math.inf]), ["action_high", "finite"], True),
    ("string-obs-dim", _meta(obs_dim="12"), ["obs_dim"], True),
    ("missing-config", _drop("config"), ["missing keys", "config"], True),
    ("config-not-a-dict", _meta(config=[1, 2]), ["config"], False),
    ("unknown-config-key", _meta(config={"no_such_option": 1}), ["config"], False),
]
TENSOR_CASES = [
    ("nan-actor-weight", _actor_tensor("mean_net.0.weight", math.nan), ["actor", "mean_net.0.weight", "finite"],
     True),
    ("inf-actor-bias", _actor_tensor("mean_net.2.bias", math.inf), ["actor", "mean_net.2.bias", "finite"], True),
    ("nan-critic", _critic_nan, ["critic", "finite"], False),
    ("missing-critic", _drop_tensor("critic"), ["critic", "missing"], False),
    ("missing-return-stats", _drop_tensor("return_rms_var"), ["return_rms_var", "missing"], False),
]


def _spoilt_copy(good: Path, tmp_path: Path, name: str, spoil: Spoil) -> Path:
    meta = json.loads(good.read_text())
    state = torch.load(good.with_suffix(".pt"), weights_only=True)
    spoil(meta, state)
    torch.save(state, tmp_path / f"{name}.pt")
    meta["weights_file"] = f"{name}.pt"
    out = tmp_path / f"{name}.json"
    out.write_text(json.dumps(meta))
    return out


@pytest.mark.parametrize(("name", "spoil", "words", "policy_too"), META_CASES + TENSOR_CASES,
                         ids=[c[0] for c in META_CASES + TENSOR_CASES])
def test_spoilt_checkpoint(trained: tuple[PASTA, Path], tmp_path: Path, name: str, spoil: Spoil,
                           words: list[str], policy_too: bool) -> None:
    bad = _spoilt_copy(trained[1], tmp_path, name, spoil)
    loaders = [PASTA.load, load_policy] if policy_too else [PASTA.load]
    for load in loaders:
        with pytest.raises(ValueError) as err:
            load(bad)
        message = str(err.value)
        assert f"{name}." in message, message  # names the file
        for word in words:
            assert word in message, message


# (id, what the .json holds, what the .pt holds, words in the message)
FILE_CASES = [
    ("random-bytes-json", bytes(range(256)) * 4, None, ["not a valid JSON checkpoint"]),
    ("empty-json", b"", None, ["not a valid JSON checkpoint"]),
    ("json-list", b"[1, 2, 3]", None, ["expected a JSON object"]),
    ("json-of-another-kind", json.dumps({"name": "my-model", "layers": 3}).encode(), None,
     ["not a PASTA checkpoint", "missing keys"]),
    ("random-bytes-pt", None, bytes(range(256)) * 4, ["cannot read the tensor file"]),
    ("truncated-pt", None, "truncate", ["cannot read the tensor file"]),
    ("pt-of-a-list", None, "list", ["expected a dict with an 'actor'"]),
]


@pytest.mark.parametrize(("name", "json_bytes", "pt_bytes", "words"), FILE_CASES, ids=[c[0] for c in FILE_CASES])
def test_file_that_is_not_a_checkpoint(trained: tuple[PASTA, Path], tmp_path: Path, name: str,
                                       json_bytes: bytes | None, pt_bytes: bytes | str | None,
                                       words: list[str]) -> None:
    good = trained[1]
    meta = json.loads(good.read_text())
    meta["weights_file"] = f"{name}.pt"
    json_path, pt_path = tmp_path / f"{name}.json", tmp_path / f"{name}.pt"
    json_path.write_bytes(json.dumps(meta).encode() if json_bytes is None else json_bytes)
    good_pt = good.with_suffix(".pt").read_bytes()
    if pt_bytes is None:
        pt_path.write_bytes(good_pt)
    elif pt_bytes == "truncate":
        pt_path.write_bytes(good_pt[: len(good_pt) // 2])
    elif pt_bytes == "list":
        torch.save([torch.zeros(3)], pt_path)
    else:
        pt_path.write_bytes(pt_bytes)
    for load in (PASTA.load, load_policy):
        with pytest.raises(ValueError) as err:
            load(json_path)
        message = str(err.value)
        assert f"{name}." in message, message
        for word in words:
            assert word in message, message


def test_a_failed_load_leaves_the_loaded_agent_unchanged(trained: tuple[PASTA, Path], tmp_path: Path) -> None:
    agent, good = trained
    loaded = PASTA.load(good)
    before = {k: v.clone() for k, v in loaded.actor.state_dict().items()}
    bad = _spoilt_copy(good, tmp_path, "late-failure", _drop_tensor("return_rms_count"))
    with pytest.raises(ValueError):
        PASTA.load(bad)
    for k, v in loaded.actor.state_dict().items():
        torch.testing.assert_close(v, before[k], rtol=0, atol=0)
    assert loaded.num_timesteps == agent.num_timesteps


@pytest.mark.parametrize("preference", [[math.nan, 1, 1, 1, 1], [math.inf, 0, 0, 0, 0], [0, 0, 0, 0, 0], [1, 1]],
                         ids=["nan", "inf", "zero-sum", "short"])
def test_a_bad_preference_override_names_the_file(trained: tuple[PASTA, Path], preference: list[float]) -> None:
    with pytest.raises(ValueError, match=r"agent\.json: preference must be 5 finite"):
        load_policy(trained[1], preference=preference)
