"""The configuration layer: every configuration class as a frozen value, importable without the solvers.

Nothing here imports CasADi, PIQP, DAQP, numba or torch (numpy at most; a test checks it in a fresh
process), so a script can build, inspect, compare and store configurations without loading the controllers.

* :mod:`~sofar_env.configs.env`: :class:`EnvConfig` (everything an environment is built from),
  :class:`RewardWeights`, :func:`apply_overrides`;
* :mod:`~sofar_env.configs.race`, :mod:`~sofar_env.configs.vehicle`, :mod:`~sofar_env.configs.opponents`,
  :mod:`~sofar_env.configs.sensing`: the world;
* :mod:`~sofar_env.configs.stack`, :mod:`~sofar_env.configs.mpc`, :mod:`~sofar_env.configs.miqp`,
  :mod:`~sofar_env.configs.refnum`: the controller;
* :mod:`~sofar_env.configs.objectives`: the reward objectives (name, term, bounds, default weight, reference
  preference);
* :mod:`~sofar_env.configs.registry`: the named controller presets and worlds, each a value with its doc;
* :mod:`~sofar_env.configs.resolve`: the one resolver (world, preset, multi-car defaults, user keys).

The implementation modules (:mod:`sofar_env.config`, :mod:`sofar_env.stack`, :mod:`sofar_env.race_config`, ...)
re-export these classes under their former names.
"""

from .env import OBJECTIVE_NAMES, REWARD_MODES, WORLD_NAMES, EnvConfig, RewardWeights, apply_overrides
from .miqp import MIQPConfig
from .mpc import BarrierParams, MPCConfig
from .objectives import OBJECTIVES, REFERENCE_PREFERENCE, Objective
from .opponents import DefenceConfig, LineConfig, OpponentConfig, PaceConfig, TrafficConfig
from .race import RaceConfig
from .refnum import HPIPMOptions, ReferenceNumerics
from .registry import STACK_PRESET_REGISTRY, WORLD_REGISTRY, register_stack_preset, stack_preset
from .resolve import multi_car_overrides, resolve_env_config
from .sensing import SensorConfig
from .stack import StackConfig
from .vehicle import AV21, AV21_DYNAMIC, DynamicParams, VehicleParams

__all__ = ["EnvConfig", "RewardWeights", "apply_overrides", "OBJECTIVE_NAMES", "REWARD_MODES", "WORLD_NAMES",
           "RaceConfig", "VehicleParams", "AV21", "DynamicParams", "AV21_DYNAMIC", "OpponentConfig", "PaceConfig",
           "LineConfig", "DefenceConfig", "TrafficConfig", "SensorConfig", "StackConfig", "MPCConfig",
           "BarrierParams", "MIQPConfig", "ReferenceNumerics", "HPIPMOptions", "Objective", "OBJECTIVES",
           "REFERENCE_PREFERENCE", "STACK_PRESET_REGISTRY", "WORLD_REGISTRY", "register_stack_preset",
           "stack_preset", "resolve_env_config", "multi_car_overrides"]
