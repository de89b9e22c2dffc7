"""The one resolver of the environments' configuration: world, preset, adapter layer and user keys, in order.

:func:`resolve_env_config` turns keyword arguments and/or a ``config=`` mapping into an
:class:`~sofar_env.configs.env.EnvConfig`; :func:`sofar_env.config.make_env_config` is this function for a
single-car environment, and the PettingZoo adapter calls it with ``multi_car=True``. The layers apply in this
order, each on top of the previous ones (a later layer wins):

1. **base**: :class:`EnvConfig` with its defaults, or the :class:`EnvConfig` given as ``config=`` (taken as it
   is; the layers below still apply on top of it);
2. **world**: the ``scenario`` key's entry of :data:`~sofar_env.configs.registry.WORLD_REGISTRY`;
3. **preset**: a ``stack`` key naming an entry of :data:`~sofar_env.configs.registry.STACK_PRESET_REGISTRY`
   replaces the controller; the world's controller settings (the dynamic world's) apply on top of it;
4. **adapter layer**: with ``multi_car=True``, :func:`multi_car_overrides` of the race the keys resolve to (no
   scripted opponents unless asked for, and the controller settings of ``race.side_lock``,
   ``race.lateral_rates``, ``race.mpc_restart_slack`` and ``race.heading_extent``);
5. **user keys**: the ``config`` mapping's, then the keywords (which win over the mapping; ``track`` and
   ``scenario`` given both ways must agree). A mapping for a sub-config changes the fields it names in the
   value so far; a dataclass instance (``stack=StackConfig(...)``) replaces the value, layers included;
6. **shortcut keys**: ``n_opponents``, ``offsets``, ``rho`` (into ``race.opponents``), ``speed_factor``,
   ``use_miqp`` (into ``stack``).

The user's keys therefore always win over the world, the preset and the multi-car defaults: a user who sets
``stack={"mpc": {"barrier": {"heading_extent": 0.0}}}`` in a multi-car race gets 0. No layer tests a value
for "unset".

Checks: an unknown key at any depth raises :class:`~sofar_env.errors.ConfigError` naming the key, its path and
the valid keys; every value is checked against its field's domain (:mod:`sofar_env.domains`) and
``race.dt`` must equal ``stack.mpc.control_dt``; an unknown world, preset or circuit is an error listing the
valid names. A call that raises returns nothing and changes nothing.
"""

from __future__ import annotations

import dataclasses
import math
import os
from collections.abc import Mapping
from typing import Any

from ..errors import ConfigError
from .env import EnvConfig, _track_problem, apply_overrides
from .race import RaceConfig
from .registry import stack_preset, world_overrides

__all__ = ["resolve_env_config", "multi_car_overrides", "SHORTCUTS"]

SHORTCUTS = {
    "n_opponents": ("race", "opponents"),
    "offsets": ("race", "opponents"),
    "rho": ("race", "opponents"),
    "speed_factor": ("stack",),
    "use_miqp": ("stack",),
}
"""Top-level keys that set a field of a nested sub-config: key -> path of that sub-config."""


def multi_car_overrides(race: RaceConfig) -> dict[str, Any]:
    """The defaults of a race with several controlled cars (the PettingZoo adapter), as overrides.

    ``race.opponents.n_opponents`` = 0 (the controlled cars only), and the controllers' settings that the race
    fields of multi-car races stand for (see :class:`~sofar_env.configs.race.RaceConfig`):

    * ``stack.miqp.alongside_gap`` = ``race.side_lock`` when it is > 0;
    * ``stack.lateral_prediction_plan`` = False when ``race.lateral_rates`` is ``"mpc"``;
    * ``stack.mpc.restart_slack`` = ``race.mpc_restart_slack`` when it is finite;
    * ``stack.mpc.barrier.heading_extent`` = ``race.heading_extent`` when it is > 0.

    A race field that is off adds nothing (the controller keeps its own value). The user's own keys apply after
    these (:func:`resolve_env_config`, layer 5).
    """
    stack: dict[str, Any] = {}
    if race.side_lock > 0:
        stack["miqp"] = {"alongside_gap": race.side_lock}
    if race.lateral_rates == "mpc":
        stack["lateral_prediction_plan"] = False
    if math.isfinite(race.mpc_restart_slack):
        stack.setdefault("mpc", {})["restart_slack"] = race.mpc_restart_slack
    if race.heading_extent > 0:
        stack.setdefault("mpc", {})["barrier"] = {"heading_extent": race.heading_extent}
    return {"race": {"opponents": {"n_opponents": 0}}, "stack": stack}


def _same_track(a: Any, b: Any) -> bool:
    """Whether two track values (name, alias, folder path or Track) name the same circuit."""
    from ..tracks import Track
    from ..tracks.names import resolve_track_name

    if isinstance(a, Track) or isinstance(b, Track):
        return a is b

    def key(t: Any) -> Any:
        if isinstance(t, str):
            try:
                return resolve_track_name(t)
            except ValueError:
                pass
        return os.path.realpath(os.path.expanduser(os.fspath(t))) if isinstance(t, (str, os.PathLike)) else t

    return key(a) == key(b)


def _check_agreement(config: Mapping[str, Any], kwargs: Mapping[str, Any]) -> None:
    """Raise :class:`ConfigError` when ``track`` or ``scenario`` is in both ``config`` and ``kwargs`` with values that
    differ (the registered ids pass both as keywords), or when ``config["track"]`` names no circuit."""
    if "track" in config:
        problem = _track_problem(config["track"])
        if problem is not None:
            raise ConfigError(f"config['track']: {problem}")
        if "track" in kwargs and not _same_track(config["track"], kwargs["track"]):
            raise ConfigError(
                f"config['track'] = {config['track']!r} conflicts with track={kwargs['track']!r} (the circuit of a "
                "registered id, or a keyword): pass track= alone to choose the circuit, or make the id of that "
                "circuit (SOfAR-<Circuit>-v0; SOfAR-Custom-v0 for a circuit folder or a Track)")
    if "scenario" in config and "scenario" in kwargs:
        a, b = config["scenario"], kwargs["scenario"]
        norm = (lambda v: v.strip().lower() if isinstance(v, str) else v)
        if norm(a) != norm(b):
            raise ConfigError(f"config['scenario'] = {a!r} conflicts with scenario={b!r} (the world of a registered "
                              "id, or a keyword): pass scenario= alone, or make the id of that world")




def resolve_env_config(config: EnvConfig | Mapping[str, Any] | None = None, keys: Mapping[str, Any] | None = None,
                       *, multi_car: bool = False) -> EnvConfig:
    """The :class:`EnvConfig` of ``config`` (an EnvConfig, a mapping of keys, or None) and ``keys`` (the keyword
    keys of an environment, which win over the mapping's), with the layers of the module docstring applied in
    their order; ``multi_car`` adds the adapter layer of :func:`multi_car_overrides`. Raises
    :class:`ConfigError` for an invalid key or value."""
    kwargs = dict(keys or {})
    if not multi_car:
        return _resolve(config, kwargs, None)
    race = _resolve(config, kwargs, None).race  # what the keys make of the race, which the layer reads
    return _resolve(config, kwargs, multi_car_overrides(race))


def _resolve(config: Any, kwargs: Mapping[str, Any], layer: Mapping[str, Any] | None) -> EnvConfig:
    if isinstance(config, Mapping):
        _check_agreement(config, kwargs)
    if isinstance(config, EnvConfig):
        base, items = config, {}
    elif config is None:
        base, items = EnvConfig(), {}
    elif isinstance(config, Mapping):
        base, items = EnvConfig(), dict(config)
    else:
        raise ConfigError(f"config must be an EnvConfig or a mapping, got {type(config).__name__}")
    items.update(kwargs)
    # 2. the world
    world_stack = None
    if "scenario" in items:
        name = items.pop("scenario")
        try:
            overrides = world_overrides(name)
        except ValueError as exc:
            raise ConfigError(f"scenario: {exc}") from None
        world_stack = overrides.get("stack")
        base = apply_overrides(base, {**overrides, "scenario": name.strip().lower()})
    # 3. the preset, with the world's controller settings on top
    layer_stack = (layer or {}).get("stack") or None
    if isinstance(items.get("stack"), str):
        try:
            preset = stack_preset(items["stack"])
        except ValueError as exc:
            raise ConfigError(f"stack: {exc}") from None
        stack = apply_overrides(preset, world_stack, "stack") if world_stack else preset
        # 4. the adapter layer's controller settings (below the user's other keys)
        items["stack"] = apply_overrides(stack, layer_stack, "stack") if layer_stack else stack
        layer_stack = None
    # 4. the adapter layer
    if layer:
        base = apply_overrides(base, {k: v for k, v in layer.items() if k != "stack" or layer_stack})
    # 5. the user's keys; 6. the shortcuts, after any explicit sub-config value
    nested: dict[str, Any] = {}
    for key in list(items):
        if key in SHORTCUTS:
            nested[key] = items.pop(key)
    fields = {f.name for f in dataclasses.fields(EnvConfig) if f.init}
    for key in items:
        if key not in fields:
            shortcuts = ", ".join(f"{k} (= {'.'.join(p)}.{k})" for k, p in SHORTCUTS.items())
            raise ConfigError(f"unknown configuration key {key!r}; valid keys: {', '.join(sorted(fields))}; "
                              f"shortcuts: {shortcuts}")
    cfg = apply_overrides(base, items)
    for key, value in nested.items():
        tree: dict[str, Any] = {key: value}
        for part in reversed(SHORTCUTS[key]):
            tree = {part: tree}
        cfg = apply_overrides(cfg, tree)
    return cfg
