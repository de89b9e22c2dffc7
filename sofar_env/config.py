"""Configuration of the SOfAR environments: frozen dataclasses and the one place that builds them.

:class:`EnvConfig` gathers everything an environment needs: the circuit, the
world (:class:`~sofar_env.race.RaceConfig`), the controller
(:class:`~sofar_env.stack.StackConfig`), the decision interval and the reward
settings. :func:`make_env_config` turns keyword arguments and/or a ``config=``
mapping into one, validating as it goes:

* top-level keys are the fields of :class:`EnvConfig` plus the shortcuts
  ``n_opponents``, ``offsets``, ``rho`` (into ``race.opponents``) and
  ``speed_factor``, ``use_miqp`` (into ``stack``);
* ``scenario`` names the world, ``"paper"`` (default), ``"interactive"`` or ``"dynamic"``
  (see :mod:`sofar_env.scenarios`); its overrides apply first, the other keys on top
  (a named ``stack`` preset gets the world's stack settings, if any, before the user's);
* ``stack`` may also name a controller preset, ``"sofar"`` (the default) or
  ``"paper"`` (the paper's Algorithm 1 as written; see
  :func:`~sofar_env.stack.stack_preset`); the other keys apply on top of it;
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

import dataclasses
import math
import os
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .domains import check_fields, choice, custom, flag, integer, nested, real
from .errors import ConfigError
from .race import RaceConfig
from .scenarios import SCENARIOS

__all__ = [
    "OBJECTIVE_NAMES",
    "REWARD_MODES",
    "ConfigError",
    "RewardWeights",
    "EnvConfig",
    "make_env_config",
    "apply_overrides",
]

OBJECTIVE_NAMES: tuple[str, ...] = ("safety", "overtakes", "progress", "barrier_margin", "gamma_smoothness")
"""Names of the reward objectives, in the order of the reward vector."""

REWARD_MODES = ("scalar", "vector")

_SHORTCUTS = {
    "n_opponents": ("race", "opponents"),
    "offsets": ("race", "opponents"),
    "rho": ("race", "opponents"),
    "speed_factor": ("stack",),
    "use_miqp": ("stack",),
}
"""Top-level keys that set a field of a nested sub-config: key -> path of that sub-config."""


@dataclass(frozen=True)
class RewardWeights:
    """Weights of the scalar reward ``weights . reward_vector`` (one per objective)."""

    safety: float = real(10.0)
    """Weight of the safety term (-1 on collision or leaving the track)."""
    overtakes: float = real(1.0)
    """Weight of the overtake count (+1 per overtake)."""
    progress: float = real(0.05)
    """Weight of the normalised progress (about 1 per control step at the speed profile)."""
    barrier_margin: float = real(0.5)
    """Weight of the barrier-margin penalty (in [-1, 0] per control step)."""
    gamma_smoothness: float = real(0.1)
    """Weight of the gamma-smoothness penalty -|gamma_t - gamma_{t-1}|."""

    def __post_init__(self) -> None:
        check_fields(self, "reward_weights")

    def as_array(self) -> np.ndarray:
        """The weights as a float64 array in the order of :data:`OBJECTIVE_NAMES`."""
        return np.array([getattr(self, name) for name in OBJECTIVE_NAMES], dtype=float)


def _stack_config_class() -> type:
    from .stack import StackConfig  # imports the controllers (CasADi): only when an env is configured

    return StackConfig


def _default_stack_config():
    return _stack_config_class()()


def _track_problem(track: Any) -> str | None:
    """Why ``track`` names no circuit (None when it does): a shipped name or alias, a folder, or a Track."""
    from .tracks import Track
    from .tracks.names import ALIASES, unknown_name_error

    if isinstance(track, Track):
        return None
    if not isinstance(track, (str, os.PathLike)):
        return (f"must be a circuit name, a circuit folder or a sofar_env.tracks.Track, got {track!r} "
                f"({type(track).__name__})")
    if isinstance(track, str) and track.strip().lower() in ALIASES:
        return None
    if Path(os.fspath(track)).expanduser().is_dir():
        return None
    if isinstance(track, os.PathLike) or os.sep in track:
        return f"{os.fspath(track)!r} is not a circuit folder"
    return str(unknown_name_error(track))


@dataclass(frozen=True)
class EnvConfig:
    """Everything a SOfAR environment is built from."""

    scenario: str = choice("paper", SCENARIOS)
    """The world (:mod:`sofar_env.scenarios`): ``"paper"``, ``"interactive"`` or ``"dynamic"``. Set through the ``scenario``
    key, which applies the scenario's overrides before the other keys."""
    track: Any = custom("LagunaSeca", _track_problem, "a circuit name, a circuit folder or a Track")
    """Circuit name (``LagunaSeca``, ``Monza``, ``Indianapolis``, ``Kentucky``, or an alias), a circuit folder path,
    or a :class:`~sofar_env.tracks.Track` (used as is; see the ``SOfAR-Custom-v0`` id)."""
    decision_interval: int = integer(1, ge=1)
    """The policy acts every this many control steps; gamma is held in between and the rewards are summed."""
    observation: str = choice("paper", ("paper", "extended"))
    """Observation layout (:mod:`sofar_env.observation`): ``"paper"``, the 12 values of the paper world, or
    ``"extended"``, 16 values that add the two nearest opponents' sensed lateral rates, the heading error and
    the smallest barrier value (the default of the interactive world)."""
    reward_mode: str = choice("scalar", REWARD_MODES)
    """``"scalar"``: reward = weights . vector (a float); ``"vector"``: the float32 reward vector."""
    reward_weights: RewardWeights = nested(RewardWeights)
    """Weights of the scalar reward."""
    initial_gamma: float = real(0.5, gt=0.0, le=1.0)
    """gamma_{t-1} assumed at the first step of an episode (for the smoothness term) [-]."""
    stall_speed: float = real(1.0, ge=0.0, unit="m/s")
    """A controlled car slower than this is standing still, for the stall rule [m/s] (walking pace; the
    slowest opponent of the paper's world at the lowest pace ratio of Table I moves at 1.75 m/s)."""
    stall_seconds: float | None = real(20.0, ge=0.0, optional="off", unit="s")
    """The stall rule: a car that stays slower than ``stall_speed`` for this long without interruption
    terminates its episode with ``info["stalled"] = True`` and ``is_success = False`` [s]. 20 s is a
    tenth of the 200 s race: far longer than any stop the controller makes to let a car clear, so it only
    fires when the car is stuck (behind a car it cannot pass, or in a barrier deadlock). ``None`` or 0
    turns the rule off."""
    timing_info: bool = flag(False)
    """Also report the wall-clock solve times ``mpc_time_ms`` / ``miqp_time_ms`` in ``info``. Off by default:
    they are the only info values that differ between two runs with the same seed, and conformance checks
    that compare infos exactly (Gymnasium's ``check_env``, PettingZoo's seed test) fail with them."""
    race: RaceConfig = nested(RaceConfig)
    """The world: time step, duration, start distribution, vehicle, opponents."""
    stack: Any = nested(_stack_config_class, factory=_default_stack_config)
    """The controller (:class:`~sofar_env.stack.StackConfig`): speed factor, MIQP, MPC settings."""

    def __post_init__(self) -> None:
        """Check every field's domain (:mod:`sofar_env.domains`), then that the MPC's control interval is the
        world's time step; raises :class:`ConfigError` naming the key."""
        check_fields(self)
        dt, mpc_dt = self.race.dt, self.stack.mpc.control_dt
        if not math.isclose(mpc_dt, dt, rel_tol=1e-9, abs_tol=0.0):
            raise ConfigError(
                f"race.dt ({dt:g} s) and stack.mpc.control_dt ({mpc_dt:g} s) must be equal: the MPC plans and "
                f"certifies its barrier over one plant period and shifts its plan by it every step. Set both, "
                f"e.g. config={{'race': {{'dt': {dt!r}}}, 'stack': {{'mpc': {{'control_dt': {dt!r}}}}}}}")

    # read-only views of the shortcut keys
    @property
    def n_opponents(self) -> int:
        return self.race.opponents.n_opponents

    @property
    def offsets(self) -> tuple[float, ...]:
        return self.race.opponents.offsets

    @property
    def rho(self) -> float:
        return self.race.opponents.rho

    @property
    def speed_factor(self) -> float:
        return self.stack.speed_factor

    @property
    def use_miqp(self) -> bool:
        return self.stack.use_miqp

    @property
    def stall_steps(self) -> int | None:
        """Control steps of the stall rule (``stall_seconds / race.dt`` rounded up), None when it is off."""
        if not self.stall_seconds:
            return None
        return max(1, int(np.ceil(self.stall_seconds / self.race.dt - 1e-9)))

    @property
    def control_steps(self) -> int:
        """Control steps in one episode (the race duration over dt)."""
        return self.race.max_steps


def apply_overrides(base: Any, overrides: Mapping[str, Any], path: str = "") -> Any:
    """``base`` (a dataclass instance) with the fields in ``overrides`` replaced, recursively.

    A field whose current value is a dataclass accepts a mapping (applied to that value)
    or an instance of the same class. Lists become tuples for tuple fields. Unknown keys
    raise :class:`ConfigError`.
    """
    if not isinstance(overrides, Mapping):
        raise ConfigError(f"{path or 'config'} must be a mapping, got {type(overrides).__name__}")
    names = {f.name for f in dataclasses.fields(base) if f.init}
    changes = {}
    for key, value in overrides.items():
        where = f"{path}.{key}" if path else str(key)
        if key not in names:
            raise ConfigError(
                f"unknown configuration key {where!r}; valid keys{' of ' + path if path else ''}: {', '.join(sorted(names))}"
            )
        current = getattr(base, key)
        if dataclasses.is_dataclass(current) and not isinstance(current, type):
            if isinstance(value, Mapping):
                value = apply_overrides(current, value, where)
            elif not isinstance(value, type(current)):
                raise ConfigError(f"{where} must be a {type(current).__name__} or a mapping, got {type(value).__name__}")
        elif isinstance(current, tuple) and isinstance(value, (list, np.ndarray)):
            value = tuple(np.asarray(value).tolist())
        changes[key] = value
    try:
        return dataclasses.replace(base, **changes)
    except ConfigError:
        raise
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"invalid value in {path or 'config'}: {exc}") from exc


def _same_track(a: Any, b: Any) -> bool:
    """Whether two track values (name, alias, folder path or Track) name the same circuit."""
    from .tracks import Track
    from .tracks.names import resolve_track_name

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


def make_env_config(config: EnvConfig | Mapping[str, Any] | None = None, **kwargs: Any) -> EnvConfig:
    """Build an :class:`EnvConfig` from a config object or mapping plus keyword overrides.

    Keyword arguments win over the mapping, except that ``track`` and ``scenario`` given both ways must agree
    (:class:`ConfigError` otherwise). See the module docstring for the accepted keys.
    """
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
    scenario_stack = None
    if "scenario" in items:
        from .scenarios import scenario_overrides

        name = items.pop("scenario")
        try:
            overrides = scenario_overrides(name)
        except ValueError as exc:
            raise ConfigError(f"scenario: {exc}") from None
        scenario_stack = overrides.get("stack")
        base = apply_overrides(base, {**overrides, "scenario": name.strip().lower()})
    if isinstance(items.get("stack"), str):
        from .stack import stack_preset

        try:
            preset = stack_preset(items["stack"])
        except ValueError as exc:
            raise ConfigError(f"stack: {exc}") from None
        # a world's stack settings (the dynamic plant's limits and weights) apply to any preset
        items["stack"] = apply_overrides(preset, scenario_stack, "stack") if scenario_stack else preset
    # route the shortcut keys into their sub-config, after any explicit sub-config value
    nested: dict[str, Any] = {}
    for key in list(items):
        if key in _SHORTCUTS:
            nested[key] = items.pop(key)
    fields = {f.name for f in dataclasses.fields(EnvConfig) if f.init}
    for key in items:
        if key not in fields:
            shortcuts = ", ".join(f"{k} (= {'.'.join(p)}.{k})" for k, p in _SHORTCUTS.items())
            raise ConfigError(f"unknown configuration key {key!r}; valid keys: {', '.join(sorted(fields))}; "
                              f"shortcuts: {shortcuts}")
    cfg = apply_overrides(base, items)
    for key, value in nested.items():
        sub_path = _SHORTCUTS[key]
        tree: dict[str, Any] = {key: value}
        for part in reversed(sub_path):
            tree = {part: tree}
        cfg = apply_overrides(cfg, tree)
    return cfg
