"""The fields of a PASTA checkpoint's JSON half and their checks (format_version 1).

:func:`validate_metadata` checks every field that :func:`~sofar_agents.pasta.checkpoint.save_agent` writes,
before anything is built from it, and raises ``ValueError`` naming the file and the field for any value of
the wrong type or out of range. Keys it does not know are left alone. Fields:

==================  =======================================================================================
``format_version``  the integer 1 (required)
``algorithm``       ``"PASTA"``
``weights_file``    the file name (or path) of the tensor half, a non-empty string
``weights_sha256``  the SHA-256 of the tensor file's bytes (64 hex digits); absent in checkpoints written
                    before it, which are then read without the check
``obs_dim``         observation size, a positive integer (required)
``n_objectives``    K, a positive integer (required)
``objective_names`` K strings
``act_dim``         a positive integer, the length of the action bounds
``action_low``,     the action (gamma) bounds: lists of the same positive length of finite numbers in
``action_high``     ``[GAMMA_MIN, GAMMA_MAX]`` = [0.05, 1] with ``action_low < action_high`` (required)
``action_squashing``  ``"sigmoid"``, ``"clip"``, ``"sigmoid-clip"`` or ``"log-sigmoid"``, as ``config.action_squashing``
                    (``"sigmoid-clip"``: ``config.squash_margin`` in (0, 1], default 0.05)
``activation``      ``"tanh"``
``preference``      K finite, non-negative numbers with a positive sum (required)
``seed``            the agent's seed, an integer >= 0
``config``          the PASTA config, a JSON object (required; its values are checked by ``PASTAConfig``
                    when an agent is built, ``hidden_sizes`` here: a list of positive integers)
``state``           ``num_timesteps`` and ``num_updates`` (integers >= 0), ``mu`` (finite, > 0),
                    ``last_conflict`` (in [0, 1]), ``train_time_s`` (finite, >= 0), ``rng`` (the state of
                    the agent's numpy generator, a PCG64 ``bit_generator.state``)
``training``        free-form metadata of the run, a JSON object
``rollout``         the rollout state to resume from (:mod:`sofar_agents.pasta.resume`), or absent
==================  =======================================================================================
"""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import Any

import numpy as np

from sofar_agents.pasta.config import SQUASHINGS
from sofar_env.constants import GAMMA_MAX, GAMMA_MIN

__all__ = ["FORMAT_VERSION", "REQUIRED_KEYS", "validate_metadata", "check_generator_state", "is_int"]

FORMAT_VERSION = 1
"""Version of the PASTA checkpoint format written and accepted by this package."""

REQUIRED_KEYS = ("format_version", "obs_dim", "n_objectives", "action_low", "action_high", "preference", "config")
"""Keys every checkpoint has; the others may be absent (older checkpoints)."""


def is_int(value: Any) -> bool:
    """A JSON integer (not a boolean)."""
    return isinstance(value, int) and not isinstance(value, bool)


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _fail(json_path: Path, field: str, what: str, value: Any) -> ValueError:
    return ValueError(f"{json_path}: {field} {what}, got {value!r}")


def validate_metadata(meta: Any, json_path: Path) -> None:
    """Check every known field of a checkpoint's JSON (the module docstring); ``ValueError`` naming
    ``json_path`` and the field at the first bad one. Nothing is changed."""
    if not isinstance(meta, dict):
        raise ValueError(f"{json_path}: expected a JSON object")
    missing = [k for k in REQUIRED_KEYS if k not in meta]
    if missing:
        raise ValueError(f"{json_path}: not a PASTA checkpoint, missing keys {missing}")
    if not is_int(meta["format_version"]) or meta["format_version"] != FORMAT_VERSION:
        raise ValueError(
            f"{json_path}: checkpoint format_version {meta['format_version']!r} is not supported "
            f"(this version of sofar_agents reads format_version {FORMAT_VERSION})"
        )
    if "algorithm" in meta and meta["algorithm"] != "PASTA":
        raise _fail(json_path, "algorithm", "must be 'PASTA'", meta["algorithm"])
    if "weights_file" in meta and not (isinstance(meta["weights_file"], str) and meta["weights_file"]):
        raise _fail(json_path, "weights_file", "must be a non-empty file name", meta["weights_file"])
    digest = meta.get("weights_sha256")
    if "weights_sha256" in meta and not (isinstance(digest, str) and re.fullmatch(r"[0-9a-f]{64}", digest)):
        raise _fail(json_path, "weights_sha256", "must be 64 lower-case hex digits", digest)
    for key in ("obs_dim", "n_objectives"):
        if not is_int(meta[key]) or meta[key] < 1:
            raise ValueError(f"{json_path}: {key} must be a positive integer, got {meta[key]!r}")
    k = meta["n_objectives"]
    _check_preference(meta, k, json_path)
    if "objective_names" in meta:
        names = meta["objective_names"]
        if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
            raise _fail(json_path, "objective_names", "must be a list of strings", names)
        if len(names) != k:
            raise ValueError(f"{json_path}: {len(names)} objective names for {k} objectives")
    _check_bounds(meta, json_path)
    _check_config(meta, json_path)
    if "seed" in meta and not (is_int(meta["seed"]) and meta["seed"] >= 0):
        raise _fail(json_path, "seed", "must be an integer >= 0", meta["seed"])
    if "state" in meta:
        _check_state(meta["state"], json_path)
    if "training" in meta and not isinstance(meta["training"], dict):
        raise _fail(json_path, "training", "must be a JSON object", meta["training"])


def _finite_vector(meta: dict[str, Any], key: str, json_path: Path) -> np.ndarray:
    """``meta[key]`` as a 1-D float array; ``ValueError`` naming the file and the field unless finite."""
    value = meta[key]
    if not isinstance(value, list) or not all(_is_number(v) for v in value):
        raise ValueError(f"{json_path}: {key} must be a list of numbers, got {value!r}")
    arr = np.asarray(value, dtype=np.float64)
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{json_path}: {key} must be finite, got {value}")
    return arr


def _check_preference(meta: dict[str, Any], k: int, json_path: Path) -> None:
    preference = _finite_vector(meta, "preference", json_path)
    if len(preference) != k:
        raise ValueError(f"{json_path}: preference has {len(preference)} entries for {k} objectives")
    if np.any(preference < 0):
        raise ValueError(f"{json_path}: preference must be non-negative, got {meta['preference']}")
    if not (np.isfinite(preference.sum()) and preference.sum() > 0):
        raise ValueError(f"{json_path}: preference must sum to a positive finite value, got {meta['preference']}")


def _check_bounds(meta: dict[str, Any], json_path: Path) -> None:
    low = _finite_vector(meta, "action_low", json_path)
    high = _finite_vector(meta, "action_high", json_path)
    if len(low) != len(high) or len(low) == 0:
        raise ValueError(f"{json_path}: action_low and action_high differ in length or are empty")
    for key, arr in (("action_low", low), ("action_high", high)):
        if np.any(arr < GAMMA_MIN) or np.any(arr > GAMMA_MAX):
            raise ValueError(f"{json_path}: {key} must lie in the gamma range [{GAMMA_MIN}, {GAMMA_MAX}], "
                             f"got {meta[key]}")
    if np.any(low >= high):
        raise ValueError(f"{json_path}: action_low {meta['action_low']} must lie below action_high "
                         f"{meta['action_high']} in every component")
    if "act_dim" in meta and not (is_int(meta["act_dim"]) and meta["act_dim"] == len(low)):
        raise _fail(json_path, "act_dim", f"must be the length of the action bounds ({len(low)})", meta["act_dim"])


def _check_config(meta: dict[str, Any], json_path: Path) -> None:
    config = meta["config"]
    if not isinstance(config, dict):
        raise ValueError(f"{json_path}: config must be a JSON object, got {type(config).__name__}")
    squashing = meta.get("action_squashing", "sigmoid")
    if squashing not in SQUASHINGS:
        raise _fail(json_path, "action_squashing", f"must be one of {', '.join(SQUASHINGS)}", squashing)
    if meta.get("activation", "tanh") != "tanh":
        raise _fail(json_path, "activation", "must be 'tanh'", meta.get("activation"))
    if config.get("action_squashing", "sigmoid") != squashing:
        raise ValueError(f"{json_path}: action_squashing {squashing!r} disagrees with the config's "
                         f"{config.get('action_squashing', 'sigmoid')!r}")
    margin = config.get("squash_margin", 0.05)
    if not (isinstance(margin, (int, float)) and not isinstance(margin, bool) and 0.0 < margin <= 1.0):
        raise _fail(json_path, "config.squash_margin", "must be a number in (0, 1]", margin)
    hidden = config.get("hidden_sizes", [1])
    if not isinstance(hidden, list) or not all(is_int(h) and h > 0 for h in hidden):
        raise _fail(json_path, "config.hidden_sizes", "must be a list of positive integers", hidden)


def _check_state(state: Any, json_path: Path) -> None:
    if not isinstance(state, dict):
        raise _fail(json_path, "state", "must be a JSON object", state)
    for key in ("num_timesteps", "num_updates"):
        if key in state and not (is_int(state[key]) and state[key] >= 0):
            raise _fail(json_path, f"state.{key}", "must be an integer >= 0", state[key])
    checks = {"mu": (lambda v: v > 0, "a finite number > 0"),
              "last_conflict": (lambda v: 0 <= v <= 1, "a number in [0, 1]"),
              "train_time_s": (lambda v: v >= 0, "a finite number >= 0")}
    for key, (ok, what) in checks.items():
        if key in state and not (_is_number(state[key]) and math.isfinite(state[key]) and ok(state[key])):
            raise _fail(json_path, f"state.{key}", f"must be {what}", state[key])
    if "rng" in state:
        check_generator_state(state["rng"], f"{json_path}: state.rng")
        if state["rng"]["bit_generator"] != "PCG64":
            raise _fail(json_path, "state.rng", "must be a PCG64 state (the agent's generator)", state["rng"])


def check_generator_state(state: Any, where: str) -> None:
    """Raise ``ValueError`` starting with ``where`` unless ``state`` is a numpy bit generator's ``state``
    (a dict naming the bit generator, which accepts it)."""
    name = state.get("bit_generator") if isinstance(state, dict) else None
    bit_generator = getattr(np.random, name, None) if isinstance(name, str) else None
    if not (isinstance(bit_generator, type) and issubclass(bit_generator, np.random.BitGenerator)):
        raise ValueError(f"{where} must be the state of a numpy bit generator, got {state!r}")
    try:
        bit_generator().state = state
    except (TypeError, ValueError, KeyError, OverflowError) as err:
        raise ValueError(f"{where} is not a valid {name} state ({err})") from err
