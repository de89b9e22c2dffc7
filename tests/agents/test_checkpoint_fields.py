"""Every field of a checkpoint's JSON is checked on loading: a value of the wrong type or out of range gives a
ValueError naming the file and the field, from PASTA.load and from load_policy alike (never a bare TypeError,
never a policy that acts outside the gamma range)."""

from __future__ import annotations

import copy
import json
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from sofar_agents import PASTA
from sofar_agents.pasta.env_reconstruction import SIDECAR_SUFFIX
from sofar_agents.policies import load_policy


def _set(path: str, value: Any) -> Callable[[dict], None]:
    """Set the dotted ``path`` of the metadata to ``value``."""
    def spoil(meta: dict) -> None:
        *parents, last = path.split(".")
        node = meta
        for key in parents:
            node = node[key]
        node[last] = copy.deepcopy(value)
    return spoil


_MT19937 = {"bit_generator": "MT19937", "state": {"key": list(range(624)), "pos": 624}, "has_uint32": 0,
            "uinteger": 0}

# (id, spoil, the field the message must name)
CASES: list[tuple[str, Callable[[dict], None], str]] = [
    ("objective-names-a-number", _set("objective_names", 5), "objective_names"),
    ("objective-names-of-numbers", _set("objective_names", [1, 2, 3, 4, 5]), "objective_names"),
    ("objective-names-too-few", _set("objective_names", ["a", "b"]), "objective names"),
    ("action-high-above-gamma", _set("action_high", [2.45]), "action_high"),
    ("action-low-below-gamma", _set("action_low", [0.01]), "action_low"),
    ("action-low-negative", _set("action_low", [-1.0]), "action_low"),
    ("act-dim-wrong", _set("act_dim", 2), "act_dim"),
    ("act-dim-a-string", _set("act_dim", "1"), "act_dim"),
    ("seed-a-string", _set("seed", "7"), "seed"),
    ("seed-negative", _set("seed", -1), "seed"),
    ("algorithm-other", _set("algorithm", "PPO"), "algorithm"),
    ("weights-file-a-number", _set("weights_file", 5), "weights_file"),
    ("digest-not-hex", _set("weights_sha256", "abc"), "weights_sha256"),
    ("activation-other", _set("activation", "relu"), "activation"),
    ("squashing-other", _set("action_squashing", "tanh"), "action_squashing"),
    ("format-version-true", _set("format_version", True), "format_version"),
    ("n-objectives-float", _set("n_objectives", 5.0), "n_objectives"),
    ("hidden-sizes-a-number", _set("config.hidden_sizes", 5), "config.hidden_sizes"),
    ("hidden-sizes-negative", _set("config.hidden_sizes", [64, -1]), "config.hidden_sizes"),
    ("state-a-string", _set("state", "x"), "state"),
    ("timesteps-negative", _set("state.num_timesteps", -5), "state.num_timesteps"),
    ("updates-fractional", _set("state.num_updates", 1.5), "state.num_updates"),
    ("mu-zero", _set("state.mu", 0), "state.mu"),
    ("mu-a-string", _set("state.mu", "a"), "state.mu"),
    ("conflict-above-one", _set("state.last_conflict", 2.0), "state.last_conflict"),
    ("train-time-nan", _set("state.train_time_s", math.nan), "state.train_time_s"),
    ("rng-not-a-state", _set("state.rng", {"bit_generator": "PCG64", "state": 5}), "state.rng"),
    ("rng-unknown-generator", _set("state.rng", {"bit_generator": "Nope"}), "state.rng"),
    ("rng-of-another-generator", _set("state.rng", _MT19937), "state.rng"),
    ("training-a-list", _set("training", [1]), "training"),
    ("rollout-a-string", _set("rollout", "x"), "rollout"),
    ("rollout-no-envs", _set("rollout.n_envs", 0), "rollout.n_envs"),
    ("rollout-episodes-short", _set("rollout.episodes", []), "rollout.episodes"),
    ("rollout-episode-seed-and-generators",
     _set("rollout.episodes", [{"seed": 1, "generators": {}, "options": None}]), "rollout.episodes.0"),
    ("rollout-episode-bad-generator",
     _set("rollout.episodes", [{"seed": None, "generators": {"0._np_random": {"bit_generator": "PCG64"}},
                                "options": None}]), "rollout.episodes.0.generators"),
]


@pytest.mark.parametrize(("name", "spoil", "field"), CASES, ids=[c[0] for c in CASES])
def test_a_bad_field_names_the_file_and_the_field(trained: tuple[PASTA, Path], tmp_path: Path, name: str,
                                                  spoil: Callable[[dict], None], field: str) -> None:
    good = trained[1]
    meta = json.loads(good.read_text())
    assert meta.get("rollout") is not None and meta["rollout"]["n_envs"] == 1  # the fixture's collector state
    spoil(meta)
    meta.setdefault("weights_file", "")
    if meta["weights_file"] == "agent.pt":
        meta["weights_file"] = str(good.with_suffix(".pt").resolve())  # the good tensors
    bad = tmp_path / f"{name}.json"
    bad.write_text(json.dumps(meta))
    for load in (PASTA.load, load_policy):
        with pytest.raises(ValueError) as err:
            load(bad)
        message = str(err.value)
        assert f"{name}.json" in message and field in message, message


def test_the_good_checkpoint_and_the_shipped_ones_load(trained: tuple[PASTA, Path]) -> None:
    """The checks refuse none of the checkpoints that exist: the fixture's and the shipped ones (which have no
    weights_sha256, rng or rollout)."""
    shipped = sorted(p for p in (Path(__file__).resolve().parents[2] / "sofar_agents" / "checkpoints").glob("*.json")
                     if not p.name.endswith(SIDECAR_SUFFIX))  # a sidecar is the record of a checkpoint, not one
    assert shipped
    for path in [trained[1], *shipped]:
        PASTA.load(path)
        load_policy(path)
