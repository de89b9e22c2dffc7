"""sofar_env.config_hash: a stable short hash of a resolved configuration, tested by its properties."""

from __future__ import annotations

import dataclasses
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from sofar_env.config import make_env_config
from sofar_env.config_hash import (EXCLUDED, HASH_LENGTH, canonical_config, canonical_json, config_hash,
                                   hash_of_canonical)

BASE = {"race": {"duration": 200.0}, "stack": "sofar", "scenario": "paper"}


def _cfg(**overrides):
    mapping = json.loads(json.dumps(BASE))
    track = overrides.pop("track", "LagunaSeca")
    for key, value in overrides.items():
        mapping[key] = value
    return make_env_config(mapping, track=track)


def test_shape_and_equal_configs_give_equal_hashes() -> None:
    h = config_hash(_cfg())
    assert len(h) == HASH_LENGTH and int(h, 16) >= 0
    assert config_hash(_cfg()) == h  # two separately built, equal configurations
    assert hash_of_canonical(json.loads(canonical_json(_cfg()))) == h  # read back from JSON (config.json)


@pytest.mark.parametrize("overrides", [
    {"race": {"duration": 100.0}},
    {"stack": "paper"},
    {"scenario": "interactive"},
    {"decision_interval": 2},
    {"n_opponents": 3},
    {"reward_weights": {"safety": 9.0}},
    {"stack_mpc": None},
], ids=["duration", "preset", "world", "decision-interval", "opponents", "reward-weight", "mpc-tolerance"])
def test_a_changed_setting_changes_the_hash(overrides) -> None:
    if "stack_mpc" in overrides:
        base = _cfg()
        changed = dataclasses.replace(base, stack=dataclasses.replace(
            base.stack, mpc=dataclasses.replace(base.stack.mpc, qp_eps_abs=base.stack.mpc.qp_eps_abs * 2)))
    else:
        changed = _cfg(**overrides)
    assert config_hash(changed) != config_hash(_cfg())


def _leaves(tree, path=()):
    if isinstance(tree, dict):
        for k, v in tree.items():
            yield from _leaves(v, (*path, k))
    elif isinstance(tree, list):
        for i, v in enumerate(tree):
            yield from _leaves(v, (*path, i))
    else:
        yield path, tree


def _changed(value):
    if isinstance(value, bool):
        return not value
    if isinstance(value, (int, float)):
        return value + 1
    if value is None:
        return 0
    return f"{value}x"


def test_any_field_change_changes_the_hash() -> None:
    tree = canonical_config(_cfg())
    base = hash_of_canonical(tree)
    leaves = list(_leaves(tree))
    assert len(leaves) > 100  # the whole tree: world, controller, rewards
    seen = {base}
    for path, value in leaves:
        other = json.loads(json.dumps(tree))
        node = other
        for step in path[:-1]:
            node = node[step]
        node[path[-1]] = _changed(value)
        h = hash_of_canonical(other)
        assert h not in seen, path
        seen.add(h)


def test_per_episode_fields_are_left_out() -> None:
    assert EXCLUDED == ("track", "race.opponents.rho", "stack.use_miqp")
    base = config_hash(_cfg())
    assert config_hash(_cfg(track="Monza")) == base
    assert config_hash(make_env_config(BASE, track="LagunaSeca", rho=0.7)) == base
    assert config_hash(make_env_config(BASE, track="LagunaSeca", use_miqp=False)) == base
    tree = canonical_config(_cfg())
    assert "track" not in tree and "rho" not in tree["race"]["opponents"] and "use_miqp" not in tree["stack"]


def test_key_order_and_sequence_types_do_not_matter() -> None:
    a = {"b": 1, "a": [1.5, 2.0], "c": {"y": True, "x": None}}
    b = {"c": {"x": None, "y": True}, "a": (1.5, np.float64(2.0)), "b": np.int64(1)}
    assert canonical_json(a) == canonical_json(b) == '{"a":[1.5,2.0],"b":1,"c":{"x":null,"y":true}}'
    assert config_hash(a) == config_hash(b)


def test_canonical_values() -> None:
    @dataclasses.dataclass(frozen=True)
    class C:
        x: float = 0.1
        path: Path = Path("/a/b")
        inf: float = float("inf")
        n: int = 1

    assert canonical_json(C()) == '{"inf":"inf","n":1,"path":"/a/b","x":0.1}'
    assert config_hash({"n": 1}) != config_hash({"n": 1.0})  # a field's type is part of its value
    with pytest.raises(TypeError, match="no canonical form"):
        config_hash({"f": object()})


def test_the_same_hash_in_a_fresh_process() -> None:
    code = ("from sofar_env.config import make_env_config; from sofar_env.config_hash import config_hash; "
            f"print(config_hash(make_env_config({BASE!r}, track='LagunaSeca')))")
    env = {**os.environ, "PYTHONHASHSEED": "12345"}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, env=env)
    assert out.stdout.strip() == config_hash(_cfg())


def test_a_neutral_field_at_its_default_keeps_the_hash():
    """A field added later with neutral() is left out while at its default (old tables keep their hash) and
    hashed at any other value."""
    import dataclasses

    from sofar_env.domains import neutral, real

    @dataclasses.dataclass(frozen=True)
    class Before:
        a: float = real(1.0)

    @dataclasses.dataclass(frozen=True)
    class After:
        a: float = real(1.0)
        fix: float = neutral(real(0.0, ge=0.0))

    assert config_hash(After()) == config_hash(Before())
    assert config_hash(After(fix=0.5)) != config_hash(Before())
    assert config_hash(After(fix=0.5)) != config_hash(After(fix=0.25))


def test_neutral_needs_a_plain_default():
    import dataclasses

    import pytest

    from sofar_env.domains import neutral

    with pytest.raises(TypeError, match="plain default"):
        neutral(dataclasses.field(default_factory=list))
    with pytest.raises(TypeError, match="plain default"):
        neutral(0.0)
