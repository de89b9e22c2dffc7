"""SOfAR: safe overtaking for autonomous racing.

Importing the package registers the Gymnasium environments ``SOfAR-<Track>-v0``
(see :mod:`sofar_env.registration`) and nothing heavier: the controllers (CasADi),
rendering (matplotlib / PIL) and the PettingZoo adapter are imported on first use.

The public classes are attributes of the package, each imported when first read (so ``import sofar_env``
stays light): the environments :class:`SOfARRaceEnv` (Gymnasium; its docstring is the full
specification: ``help(sofar_env.SOfARRaceEnv)``) and :class:`SOfARParallelEnv` (PettingZoo), the
configuration :class:`EnvConfig` with :func:`make_env_config` and its parts (:class:`RewardWeights`,
:class:`RaceConfig`, :class:`OpponentConfig`, :class:`SensorConfig`, :class:`StackConfig`,
:class:`MPCConfig`, :class:`MIQPConfig`), the circuit :class:`Track` and the saved moment of an
environment :class:`EnvState`.
"""

from __future__ import annotations

import importlib
from typing import Any

from .registration import ENV_IDS, register_envs

__version__ = "0.1.0"

_LAZY = {
    "SOfARRaceEnv": "sofar_env.env",
    "SOfARParallelEnv": "sofar_env.multi_agent",
    "EnvConfig": "sofar_env.config",
    "RewardWeights": "sofar_env.config",
    "make_env_config": "sofar_env.config",
    "RaceConfig": "sofar_env.race_config",
    "OpponentConfig": "sofar_env.opponents",
    "SensorConfig": "sofar_env.sensing",
    "StackConfig": "sofar_env.stack",
    "MPCConfig": "sofar_env.control.mpc",
    "MIQPConfig": "sofar_env.planning",
    "Track": "sofar_env.tracks",
    "EnvState": "sofar_env.snapshot",
}
"""Public names imported on first use: name -> module that defines it."""

__all__ = ["ENV_IDS", "parallel_env", "__version__", *_LAZY]

register_envs()


def __getattr__(name: str) -> Any:
    """The public classes of ``_LAZY``, imported on first use (and then cached in the package)."""
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY))


def parallel_env(**kwargs):
    """PettingZoo ``ParallelEnv`` in which every car runs its own overtaking stack.

    See :func:`sofar_env.multi_agent.parallel_env` for the arguments; :func:`sofar_env.multi_agent.env`
    and :func:`sofar_env.multi_agent.raw_env` give the same race as an AEC environment.
    """
    from .multi_agent import parallel_env as _parallel_env

    return _parallel_env(**kwargs)
