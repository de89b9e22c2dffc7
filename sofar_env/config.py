"""Configuration of the SOfAR environments: the frozen dataclasses and :func:`make_env_config`.

The classes are defined in :mod:`sofar_env.configs` (values only, importable without the solvers) and
re-exported here.

:class:`EnvConfig` gathers everything an environment needs: the circuit, the
world (:class:`~sofar_env.race.RaceConfig`), the controller
(:class:`~sofar_env.stack.StackConfig`), the decision interval and the reward
settings. :func:`make_env_config` turns keyword arguments and/or a ``config=``
mapping into one, validating as it goes (:func:`sofar_env.configs.resolve.resolve_env_config`, which documents the
order in which world, preset, the multi-car defaults and the user's keys apply):

* top-level keys are the fields of :class:`EnvConfig` plus the shortcuts
  ``n_opponents``, ``offsets``, ``rho`` (into ``race.opponents``) and
  ``speed_factor``, ``use_miqp`` (into ``stack``);
* ``scenario`` names the world, ``"paper"`` (default), ``"interactive"`` or ``"dynamic"``
  (see :mod:`sofar_env.scenarios`); its overrides apply first, the other keys on top
  (a named ``stack`` preset gets the world's stack settings, if any, before the user's);
* ``stack`` may also name a controller preset, ``"sofar"`` (the default), ``"paper"`` (the paper's
  Algorithm 1 as written) or another entry of :data:`~sofar_env.configs.registry.STACK_PRESET_REGISTRY`
  (:func:`~sofar_env.stack.stack_preset`); the other keys apply on top of it;
* a value for a sub-config (``race``, ``stack``, ``reward_weights``, and their
  own nested dataclasses such as ``race.opponents`` or ``stack.mpc``) may be the
  dataclass itself or a mapping of overrides applied to the current value;
* an unknown key at any depth raises :class:`ConfigError` (a ``ValueError``)
  naming the key, its path and the valid keys; lists are accepted for tuple
  fields;
* every value is checked against the domain declared next to its field (:mod:`sofar_env.domains`: type,
  finiteness, bounds), and ``race.dt`` must equal ``stack.mpc.control_dt``; a bad value raises
  :class:`ConfigError` naming its key path (``race.opponents.gaps``, ``stack.mpc.qp_eps_abs``);
* ``track`` and ``scenario``, the keys the registered ids pass as keywords, may also appear in the
  ``config`` mapping only with the same value (the same circuit, by name, alias or path; the same world):
  ``gymnasium.make("SOfAR-LagunaSeca-v0", config={"track": "Monza"})`` is refused rather than racing
  Laguna Seca; ``track="Monza"`` as a keyword replaces the id's circuit. An unknown circuit name is an
  error that lists the valid names.

Example::

    cfg = make_env_config({"rho": 0.5, "race": {"duration": 60.0}}, decision_interval=2)
    cfg.rho, cfg.race.duration, cfg.decision_interval     # 0.5, 60.0, 2
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from .configs.env import OBJECTIVE_NAMES, REWARD_MODES, EnvConfig, RewardWeights, apply_overrides
from .configs.race import RaceConfig  # noqa: F401  (re-exported: the world's configuration)
from .configs.resolve import resolve_env_config
from .errors import ConfigError
from .scenarios import SCENARIOS  # noqa: F401  (re-exported: the worlds' names)

__all__ = [
    "OBJECTIVE_NAMES",
    "REWARD_MODES",
    "ConfigError",
    "RewardWeights",
    "EnvConfig",
    "make_env_config",
    "apply_overrides",
]


def make_env_config(config: EnvConfig | Mapping[str, Any] | None = None, **kwargs: Any) -> EnvConfig:
    """Build an :class:`EnvConfig` from a config object or mapping plus keyword overrides.

    Keyword arguments win over the mapping, except that ``track`` and ``scenario`` given both ways must agree
    (:class:`ConfigError` otherwise). See the module docstring for the accepted keys, and
    :func:`~sofar_env.configs.resolve.resolve_env_config` (of which this is the single-car form) for the order
    of the layers.
    """
    return resolve_env_config(config, kwargs)
