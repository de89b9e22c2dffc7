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
  fields.

Example::

    cfg = make_env_config({"rho": 0.5, "race": {"duration": 60.0}}, decision_interval=2)
    cfg.rho, cfg.race.duration, cfg.decision_interval     # 0.5, 60.0, 2
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .race import RaceConfig

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


class ConfigError(ValueError):
    """An invalid or unknown configuration key or value."""


@dataclass(frozen=True)
class RewardWeights:
    """Weights of the scalar reward ``weights . reward_vector`` (one per objective)."""

    safety: float = 10.0
    """Weight of the safety term (-1 on collision or leaving the track)."""
    overtakes: float = 1.0
    """Weight of the overtake count (+1 per overtake)."""
    progress: float = 0.05
    """Weight of the normalised progress (about 1 per control step at the speed profile)."""
    barrier_margin: float = 0.5
    """Weight of the barrier-margin penalty (in [-1, 0] per control step)."""
    gamma_smoothness: float = 0.1
    """Weight of the gamma-smoothness penalty -|gamma_t - gamma_{t-1}|."""

    def __post_init__(self) -> None:
        for name in OBJECTIVE_NAMES:
            value = getattr(self, name)
            if not np.isfinite(value):
                raise ConfigError(f"reward_weights.{name} must be finite, got {value!r}")

    def as_array(self) -> np.ndarray:
        """The weights as a float64 array in the order of :data:`OBJECTIVE_NAMES`."""
        return np.array([getattr(self, name) for name in OBJECTIVE_NAMES], dtype=float)


def _default_stack_config():
    from .stack import StackConfig  # imports the controllers (CasADi): only when an env is configured

    return StackConfig()


@dataclass(frozen=True)
class EnvConfig:
    """Everything a SOfAR environment is built from."""

    scenario: str = "paper"
    """The world (:mod:`sofar_env.scenarios`): ``"paper"``, ``"interactive"`` or ``"dynamic"``. Set through the ``scenario``
    key, which applies the scenario's overrides before the other keys."""
    track: Any = "LagunaSeca"
    """Circuit name (``LagunaSeca``, ``Monza``, ``Indianapolis``, ``Kentucky``, or an alias), a circuit folder path,
    or a :class:`~sofar_env.tracks.Track` (used as is; see the ``SOfAR-Custom-v0`` id)."""
    decision_interval: int = 1
    """The policy acts every this many control steps; gamma is held in between and the rewards are summed."""
    observation: str = "paper"
    """Observation layout (:mod:`sofar_env.observation`): ``"paper"``, the 12 values of the paper world, or
    ``"extended"``, 16 values that add the two nearest opponents' sensed lateral rates, the heading error and
    the smallest barrier value (the default of the interactive world)."""
    reward_mode: str = "scalar"
    """``"scalar"``: reward = weights . vector (a float); ``"vector"``: the float32 reward vector."""
    reward_weights: RewardWeights = field(default_factory=RewardWeights)
    """Weights of the scalar reward."""
    initial_gamma: float = 0.5
    """gamma_{t-1} assumed at the first step of an episode (for the smoothness term) [-]."""
    stall_speed: float = 1.0
    """A controlled car slower than this is standing still, for the stall rule [m/s] (walking pace; the
    slowest opponent of the paper's world at the lowest pace ratio of Table I moves at 1.75 m/s)."""
    stall_seconds: float | None = 20.0
    """The stall rule: a car that stays slower than ``stall_speed`` for this long without interruption
    terminates its episode with ``info["stalled"] = True`` and ``is_success = False`` [s]. 20 s is a
    tenth of the 200 s race: far longer than any stop the controller makes to let a car clear, so it only
    fires when the car is stuck (behind a car it cannot pass, or in a barrier deadlock). ``None`` or 0
    turns the rule off."""
    timing_info: bool = False
    """Also report the wall-clock solve times ``mpc_time_ms`` / ``miqp_time_ms`` in ``info``. Off by default:
    they are the only info values that differ between two runs with the same seed, and conformance checks
    that compare infos exactly (Gymnasium's ``check_env``, PettingZoo's seed test) fail with them."""
    race: RaceConfig = field(default_factory=RaceConfig)
    """The world: time step, duration, start distribution, vehicle, opponents."""
    stack: Any = field(default_factory=_default_stack_config)
    """The controller (:class:`~sofar_env.stack.StackConfig`): speed factor, MIQP, MPC settings."""

    def __post_init__(self) -> None:
        if not isinstance(self.decision_interval, (int, np.integer)) or self.decision_interval < 1:
            raise ConfigError(f"decision_interval must be an integer >= 1, got {self.decision_interval!r}")
        if self.observation not in ("paper", "extended"):
            raise ConfigError(f"observation must be 'paper' or 'extended', got {self.observation!r}")
        if self.reward_mode not in REWARD_MODES:
            raise ConfigError(f"reward_mode must be one of {REWARD_MODES}, got {self.reward_mode!r}")
        if not (0.0 < self.initial_gamma <= 1.0):
            raise ConfigError(f"initial_gamma must lie in (0, 1], got {self.initial_gamma!r}")
        if not (isinstance(self.stall_speed, (int, float, np.integer, np.floating)) and not isinstance(
                self.stall_speed, bool) and np.isfinite(self.stall_speed) and self.stall_speed >= 0.0):
            raise ConfigError(f"stall_speed must be a finite number >= 0 [m/s], got {self.stall_speed!r}")
        if self.stall_seconds is not None and not (
                isinstance(self.stall_seconds, (int, float, np.integer, np.floating))
                and not isinstance(self.stall_seconds, bool) and np.isfinite(self.stall_seconds)
                and self.stall_seconds >= 0.0):
            raise ConfigError(f"stall_seconds must be None (off) or a finite number >= 0 [s], got "
                              f"{self.stall_seconds!r}")

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


def make_env_config(config: EnvConfig | Mapping[str, Any] | None = None, **kwargs: Any) -> EnvConfig:
    """Build an :class:`EnvConfig` from a config object or mapping plus keyword overrides.

    Keyword arguments win over the mapping. See the module docstring for the accepted keys.
    """
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
