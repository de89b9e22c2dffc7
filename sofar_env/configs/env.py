"""The environment's configuration values: :class:`EnvConfig`, :class:`RewardWeights` and :func:`apply_overrides`.

Values only (numpy at most): the resolver that builds an :class:`EnvConfig` from user keys, worlds and presets
is :mod:`sofar_env.configs.resolve`; the names of worlds and presets are in :mod:`sofar_env.configs.registry`.
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

from ..domains import check_fields, choice, custom, flag, integer, nested, real
from ..errors import ConfigError
from .objectives import OBJECTIVE_NAMES, OBJECTIVES
from .race import RaceConfig
from .registry import WORLD_REGISTRY, default_stack
from .stack import StackConfig

__all__ = ["OBJECTIVE_NAMES", "REWARD_MODES", "WORLD_NAMES", "RewardWeights", "EnvConfig", "apply_overrides"]

WORLD_NAMES: tuple[str, ...] = tuple(WORLD_REGISTRY)
"""The worlds of the registry (:mod:`sofar_env.configs.registry`), the values of ``EnvConfig.scenario``."""

_WEIGHTS = {o.name: o.default_weight for o in OBJECTIVES}

REWARD_MODES = ("scalar", "vector")
"""Values of ``EnvConfig.reward_mode``."""


@dataclass(frozen=True)
class RewardWeights:
    """Weights of the scalar reward ``weights . reward_vector``: one field per objective of
    :data:`~sofar_env.configs.objectives.OBJECTIVES`, in its order, defaulting to its ``default_weight``."""

    safety: float = real(_WEIGHTS["safety"])
    """Weight of the safety term (-1 on collision or leaving the track)."""
    overtakes: float = real(_WEIGHTS["overtakes"])
    """Weight of the overtake count (+1 per overtake)."""
    progress: float = real(_WEIGHTS["progress"])
    """Weight of the normalised progress (about 1 per control step at the speed profile)."""
    barrier_margin: float = real(_WEIGHTS["barrier_margin"])
    """Weight of the barrier-margin penalty (in [-1, 0] per control step)."""
    gamma_smoothness: float = real(_WEIGHTS["gamma_smoothness"])
    """Weight of the gamma-smoothness penalty -|gamma_t - gamma_{t-1}|."""

    def __post_init__(self) -> None:
        check_fields(self, "reward_weights")

    def as_array(self) -> np.ndarray:
        """The weights as a float64 array in the order of :data:`OBJECTIVE_NAMES`."""
        return np.array([getattr(self, name) for name in OBJECTIVE_NAMES], dtype=float)


if tuple(f.name for f in dataclasses.fields(RewardWeights)) != OBJECTIVE_NAMES:  # pragma: no cover
    raise ImportError("RewardWeights must have one field per objective of sofar_env.configs.objectives, in order")


def _track_problem(track: Any) -> str | None:
    """Why ``track`` names no circuit (None when it does): a shipped name or alias, a folder, or a Track."""
    from ..tracks import Track
    from ..tracks.names import ALIASES, unknown_name_error

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

    scenario: str = choice("paper", WORLD_NAMES)
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
    """A controlled car slower than this is standing still, for the stall rule [m/s], >= 0. Decision:
    ``docs/decisions/stall-rule.md``."""
    stall_seconds: float | None = real(20.0, ge=0.0, optional="off", unit="s")
    """The stall rule: a car that stays slower than ``stall_speed`` for this long without interruption
    terminates its episode with ``info["stalled"] = True`` and ``is_success = False`` [s], >= 0. ``None``
    or 0 turns the rule off. Decision: ``docs/decisions/stall-rule.md``."""
    timing_info: bool = flag(False)
    """Also report the wall-clock solve times ``mpc_time_ms`` / ``miqp_time_ms`` in ``info``. Off by default:
    they are the only info values that differ between two runs with the same seed, and conformance checks
    that compare infos exactly (Gymnasium's ``check_env``, PettingZoo's seed test) fail with them."""
    race: RaceConfig = nested(RaceConfig)
    """The world: time step, duration, start distribution, vehicle, opponents."""
    stack: StackConfig = nested(StackConfig, factory=default_stack)
    """The controller (:class:`~sofar_env.configs.stack.StackConfig`): speed factor, MIQP, MPC settings. Default:
    the default controller, preset ``"sofar"`` (:func:`~sofar_env.configs.registry.default_stack`), which is not
    ``StackConfig()`` (that is version 1, ``"sofar-1"``, without the stall fixes)."""

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
