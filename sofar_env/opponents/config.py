"""Configuration of the opponent field, defined in :mod:`sofar_env.configs.opponents` (importable without
the compiled kernels) and re-exported here."""

from ..configs.opponents import DefenceConfig, LineConfig, OpponentConfig, PaceConfig, TrafficConfig

__all__ = ["DefenceConfig", "LineConfig", "OpponentConfig", "PaceConfig", "TrafficConfig"]
