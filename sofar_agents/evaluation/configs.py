"""The resolved configuration behind result rows: its hash per row, ``config.json`` per results folder, and the
check that rows of one strategy label come from one configuration.

* :func:`episode_config` resolves the configuration of a Table I / II episode exactly as
  :func:`~sofar_agents.evaluation.episode.make_env` builds its environment (the same mapping, through
  :func:`sofar_env.config.make_env_config`); :func:`race_config` that of a multi-agent race as
  :func:`~sofar_agents.evaluation.multi_agent.race_env` does. Their :func:`~sofar_env.config_hash.config_hash`
  is the ``config_hash`` of the rows (the episode runner checks it against the environment it ran).
* :func:`write_config_json` records, in a results folder, the full resolved configuration of every hash its
  rows carry (``config.json``: ``{"excluded": [...], "configs": {hash: canonical config}}``). An entry is
  written once: a hash already in the file is left as it is, new ones are added; each write replaces the
  file atomically (temporary file + ``os.replace``).
* :func:`check_one_config` refuses rows of one strategy label with different hashes (``ValueError`` naming
  both). Rows without a hash (files written before the column: hash ``""``) are another configuration, never
  the same as a hashed one: a label with ``""`` and a hash is refused too. Readers that select rows by resume
  key (:func:`~sofar_agents.evaluation.results.select_rows`) never mix them, since the hash is part of the key.
"""

from __future__ import annotations

import json
import logging
import os
from collections.abc import Callable, Iterable, Mapping
from functools import lru_cache
from pathlib import Path
from typing import Any

from sofar_agents.evaluation.files import write_json_atomic
from sofar_env.config_hash import EXCLUDED, canonical_config, config_hash, hash_of_canonical

__all__ = ["CONFIG_JSON", "episode_env_mapping", "episode_config", "episode_config_hash", "race_config",
           "race_config_hash", "write_config_json", "read_config_json", "check_one_config", "row_hash"]

logger = logging.getLogger(__name__)

CONFIG_JSON = "config.json"
"""Name of the file in a results folder that holds the configuration of every hash of its rows."""

_ANY_TRACK = "LagunaSeca"
"""The circuit used to resolve a configuration whose hash leaves the circuit out (any circuit gives the same)."""


def episode_env_mapping(duration: float, stack: str, scenario: str) -> dict[str, Any]:
    """The ``config`` mapping of an evaluation episode's environment (besides the id's circuit and ``use_miqp``)."""
    return {"race": {"duration": float(duration)}, "stack": stack, "scenario": scenario}


@lru_cache(maxsize=64)
def episode_config(stack: str = "sofar", scenario: str = "paper", duration: float = 200.0,
                   track: str = _ANY_TRACK, use_miqp: bool = True):
    """The :class:`~sofar_env.config.EnvConfig` of an evaluation episode, resolved as its environment is."""
    from sofar_env.config import make_env_config

    return make_env_config(episode_env_mapping(duration, stack, scenario), track=track, use_miqp=bool(use_miqp))


@lru_cache(maxsize=64)
def episode_config_hash(stack: str = "sofar", scenario: str = "paper", duration: float = 200.0) -> str:
    """The ``config_hash`` of the episodes of a table with this controller preset, world and duration."""
    return config_hash(episode_config(str(stack), str(scenario), float(duration)))


@lru_cache(maxsize=64)
def race_config(stack: str = "sofar", scenario: str = "paper", duration: float = 200.0, opponents: int = 0,
                track: str = _ANY_TRACK):
    """The :class:`~sofar_env.config.EnvConfig` of a multi-agent race, resolved as
    :func:`~sofar_agents.evaluation.multi_agent.race_env` builds it (no overrides)."""
    from sofar_env.config import make_env_config
    from sofar_env.configs.resolve import resolve_env_config

    base = make_env_config(None, stack=stack)
    keys = dict(track=track, race={"duration": float(duration)}, scenario=scenario, timing_info=False,
                **({"n_opponents": int(opponents)} if opponents else {}))
    return resolve_env_config(base, keys, multi_car=True)  # as the PettingZoo env resolves it (sofar_env.multi_agent)


@lru_cache(maxsize=64)
def race_config_hash(stack: str = "sofar", scenario: str = "paper", duration: float = 200.0,
                     opponents: int = 0) -> str:
    """The ``config_hash`` of the races of a multi-agent table."""
    return config_hash(race_config(str(stack), str(scenario), float(duration), int(opponents)))


def read_config_json(folder: str | os.PathLike) -> dict[str, dict[str, Any]]:
    """``{hash: canonical config}`` of ``folder/config.json`` (empty when there is none). Raises ``ValueError``
    naming the file when it is not such a file or an entry's content does not have its hash."""
    path = Path(folder) / CONFIG_JSON
    if not path.is_file():
        return {}
    try:
        data = json.loads(path.read_text())
        configs = data["configs"]
    except (json.JSONDecodeError, KeyError, TypeError) as err:
        raise ValueError(f"{path}: not a configuration file ({err})") from err
    if not isinstance(configs, dict):
        raise ValueError(f"{path}: 'configs' must be an object of hash -> configuration")
    for h, tree in configs.items():
        if data.get("excluded", list(EXCLUDED)) == list(EXCLUDED) and hash_of_canonical(tree) != h:
            raise ValueError(f"{path}: the configuration under {h} has hash {hash_of_canonical(tree)}")
    return configs


def write_config_json(folder: str | os.PathLike, configs: Iterable[Any]) -> Path:
    """Add the resolved configurations ``configs`` (dataclass trees) to ``folder/config.json`` under their
    hashes; entries already there are kept as they are. The file is replaced atomically, and only when an
    entry is new. Returns the path."""
    path = Path(folder) / CONFIG_JSON
    path.parent.mkdir(parents=True, exist_ok=True)
    have = read_config_json(folder)
    new = {config_hash(c): canonical_config(c) for c in configs}
    added = {h: tree for h, tree in new.items() if h not in have}
    if not added:
        return path
    write_json_atomic(path, {"excluded": list(EXCLUDED), "configs": {**have, **added}}, indent=1, sort_keys=True)
    logger.info("%s: recorded the configuration of %s", path, ", ".join(sorted(added)))
    return path


def row_hash(row: Any) -> str:
    """The ``config_hash`` of a row (a mapping or an object with the attribute); ``""`` when it has none."""
    value = row.get("config_hash") if isinstance(row, Mapping) else getattr(row, "config_hash", "")
    return str(value or "")


def check_one_config(rows: Iterable[Any], label: Callable[[Any], str], where: str = "") -> None:
    """``ValueError`` unless every group of ``rows`` under one ``label(row)`` carries one ``config_hash``.

    The message names the label and both hashes (``""``, rows without a hash, reads as "no hash"): two
    configurations under one strategy label would make one number of two controllers or worlds.
    """
    seen: dict[str, str] = {}
    for row in rows:
        name, h = label(row), row_hash(row)
        first = seen.setdefault(name, h)
        if first != h:
            a, b = (x or "no hash (written before config_hash)" for x in (first, h))
            raise ValueError(f"{where + ': ' if where else ''}rows of {name!r} come from two configurations: "
                             f"config_hash {a} and {b}; keep them apart (another label or another --out)")
