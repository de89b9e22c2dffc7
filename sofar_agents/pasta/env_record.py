"""The configuration of a PASTA agent's training environment, as its checkpoint records it.

:func:`training_env_record` resolves the environment that ``train/pasta.py`` trains in from the run
metadata the script gives the agent (``env_id``, ``env_kwargs``, ``decision_interval``, ``multi_agent``),
the same way the training envs are built (``gymnasium.make(env_id, reward_mode="vector", **env_kwargs)``,
or the PettingZoo race of ``--multi-agent``), and returns what the checkpoint's ``training`` object
records about it:

* ``env_config_hash``: :func:`sofar_env.config_hash.config_hash` of that configuration (it differs from the
  hash of evaluation rows of the same controller and world in what training sets differently: the vector
  reward mode, the decision interval, the duration);
* ``env_config``: the configuration itself in canonical form (without the per-episode key paths of
  :data:`sofar_env.config_hash.EXCLUDED`: the circuit is in ``env_id`` / ``env_kwargs``, rho is drawn per
  episode); :func:`sofar_env.config_hash.hash_of_canonical` of it is ``env_config_hash``.

Metadata without ``env_id`` (an agent not trained by the script) gives an empty record; an environment
that cannot be resolved is logged and gives an empty record too: saving a checkpoint never fails on it.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from typing import Any

__all__ = ["training_env_config", "training_env_record"]

logger = logging.getLogger(__name__)


def training_env_config(metadata: Mapping[str, Any]) -> Any:
    """The :class:`~sofar_env.config.EnvConfig` of the training environment described by ``metadata``."""
    import gymnasium as gym

    import sofar_env  # noqa: F401  (registers the ids)
    from sofar_env.config import apply_overrides, make_env_config

    kwargs = {**gym.spec(metadata["env_id"]).kwargs, **dict(metadata.get("env_kwargs") or {})}
    if metadata.get("decision_interval") is not None:
        kwargs["decision_interval"] = metadata["decision_interval"]
    kwargs.pop("render_mode", None)
    kwargs["reward_mode"] = "vector"
    config = kwargs.pop("config", None)
    cfg = make_env_config(config, **kwargs)
    if metadata.get("multi_agent") and "n_opponents" not in kwargs and not (
            isinstance(config, Mapping) and "n_opponents" in config):
        cfg = apply_overrides(cfg, {"race": {"opponents": {"n_opponents": 0}}})  # the race's default
    return cfg


def training_env_record(metadata: Mapping[str, Any]) -> dict[str, Any]:
    """``{"env_config_hash": ..., "env_config": ...}`` for ``metadata`` (module docstring), or ``{}``."""
    if not metadata.get("env_id"):
        return {}
    from sofar_env.config_hash import canonical_config, config_hash

    try:
        cfg = training_env_config(metadata)
    except Exception as err:  # noqa: BLE001 - a checkpoint is saved without the record, and that is logged
        logger.warning("the training environment %r could not be resolved for the checkpoint (%s): no "
                       "env_config_hash recorded", metadata.get("env_id"), err)
        return {}
    return {"env_config_hash": config_hash(cfg), "env_config": canonical_config(cfg)}
