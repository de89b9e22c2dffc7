"""A stable short hash of a resolved configuration: what identifies the controller and the world of a result.

Result rows name their controller preset (``stack="sofar"``) and world (``scenario="paper"``), but a preset
is a name for values that may change: a new default silently changes what every later row of that name
means. :func:`config_hash` names the values themselves.

Contract
--------
* **Input**: a resolved configuration, a tree of (frozen) dataclasses as built by
  :func:`sofar_env.config.make_env_config` (an :class:`~sofar_env.config.EnvConfig`; any dataclass tree works).
* **Canonical form** (:func:`canonical_config`, :func:`canonical_json`): the dataclass tree as nested JSON
  objects keyed by field name, serialised with sorted keys and no whitespace; tuples, lists and numpy
  arrays as lists; floats (and numpy floats) as JSON numbers in Python's ``repr`` (the shortest text that
  reads back to the same float; ``"inf"``, ``"-inf"``, ``"nan"`` as strings); bools as JSON booleans,
  ints as integers (so ``1`` and ``1.0`` differ: a field's type is part of its value); enums as their
  ``value`` (as a string); paths as strings; ``None`` as ``null``. Any other type raises ``TypeError``:
  nothing is hashed by its ``repr`` (which may hold a memory address).
* **Left out** (:data:`EXCLUDED`): what varies from episode to episode *within one table* and is recorded
  in the row itself, so that every row of a table shares one hash:

  - ``track``: the circuit (the ``track`` column; a :class:`~sofar_env.tracks.Track` object is not
    serialisable either);
  - ``race.opponents.rho``: the opponents' pace ratio (the ``rho`` column; episodes set it per reset);
  - ``stack.use_miqp``: the MIQP layer on or off (the ``use_miqp`` column; Table II runs both).

  - a field declared :func:`~sofar_env.domains.neutral` while it holds its default: a field added after
    results were made, whose default keeps their behaviour (a fix switched off), so that adding it keeps
    every existing hash; at any other value it is hashed.

  The reset seed is not part of a configuration (the ``seed`` column). Everything else is in: the
  duration, the default opponent count (which an empty ``n_opponents`` column stands for), the world's
  settings, every controller value.
* **Hash**: the first :data:`HASH_LENGTH` (12) hex digits of the SHA-256 of the canonical JSON (UTF-8).
  It depends only on the values, not on the process, the platform, dict order or ``PYTHONHASHSEED``;
  two configurations that differ in any included field have different hashes (up to SHA-256 collisions
  of 48 bits: negligible for the few configurations a project holds). Adding a field to a configuration
  class changes every hash (rows made before it carry the old hash and are not mixed with newer ones),
  unless the field is declared neutral at a default that keeps the old behaviour.
"""

from __future__ import annotations

import dataclasses
import enum
import hashlib
import json
import math
import os
from collections.abc import Mapping
from typing import Any

import numpy as np

from .domains import is_neutral_default

__all__ = ["EXCLUDED", "HASH_LENGTH", "canonical_config", "canonical_json", "config_hash", "hash_of_canonical"]

EXCLUDED: tuple[str, ...] = ("track", "race.opponents.rho", "stack.use_miqp")
"""Key paths left out of the hash (module docstring): they vary per episode within a table."""

HASH_LENGTH = 12
"""Hex digits of the hash."""


def _value(v: Any, path: str, excluded: frozenset[str]) -> Any:
    if dataclasses.is_dataclass(v) and not isinstance(v, type):
        out = {}
        for f in dataclasses.fields(v):
            where = f"{path}.{f.name}" if path else f.name
            if where not in excluded and not is_neutral_default(f, getattr(v, f.name)):
                out[f.name] = _value(getattr(v, f.name), where, excluded)
        return out
    if isinstance(v, Mapping):
        return {str(k): _value(x, f"{path}.{k}" if path else str(k), excluded) for k, x in v.items()}
    if v is None or isinstance(v, (bool, np.bool_)):
        return None if v is None else bool(v)
    if isinstance(v, enum.Enum):
        return str(v.value)
    if isinstance(v, (int, np.integer)):
        return int(v)
    if isinstance(v, (float, np.floating)):
        x = float(v)
        return x if math.isfinite(x) else repr(x)
    if isinstance(v, str):
        return v
    if isinstance(v, os.PathLike):
        return os.fspath(v)
    if isinstance(v, (tuple, list, np.ndarray)):
        seq = v.tolist() if isinstance(v, np.ndarray) else v
        return [_value(x, f"{path}[{i}]", excluded) for i, x in enumerate(seq)]
    raise TypeError(f"config_hash: {path or 'config'} is a {type(v).__name__}, which has no canonical form")


def canonical_config(config: Any, *, exclude: tuple[str, ...] = EXCLUDED) -> dict[str, Any]:
    """The configuration as plain JSON values (module docstring), without the key paths in ``exclude``
    (``exclude=()``: everything, e.g. to record a training environment in full)."""
    out = _value(config, "", frozenset(exclude))
    if not isinstance(out, dict):
        raise TypeError(f"config_hash: expected a dataclass or a mapping, got {type(config).__name__}")
    return out


def canonical_json(config: Any, *, exclude: tuple[str, ...] = EXCLUDED) -> str:
    """:func:`canonical_config` as JSON text: sorted keys, no whitespace, ASCII."""
    return _dumps(canonical_config(config, exclude=exclude))


def _dumps(tree: Mapping[str, Any]) -> str:
    return json.dumps(tree, sort_keys=True, separators=(",", ":"), ensure_ascii=True, allow_nan=False)


def hash_of_canonical(tree: Mapping[str, Any]) -> str:
    """The hash of an already canonical tree (e.g. one read back from a ``config.json``): equal to
    :func:`config_hash` of the configuration it was made from."""
    return hashlib.sha256(_dumps(tree).encode("utf-8")).hexdigest()[:HASH_LENGTH]


def config_hash(config: Any) -> str:
    """The 12-hex-digit hash of ``config`` without the :data:`EXCLUDED` key paths (module docstring)."""
    return hash_of_canonical(canonical_config(config))
