"""Configuration of the race world (:class:`RaceConfig`), defined in :mod:`sofar_env.configs.race` (importable
without the compiled kernels and the solvers) and re-exported here."""

from .configs.race import (GRID_MIN_GAP, LATERAL_RATES, MAX_SPEED_FACTOR, MAX_START_SPEED_FACTOR, PLANTS,
                           START_EDGE_MARGIN, RaceConfig, _is_real)

__all__ = ["RaceConfig", "PLANTS", "LATERAL_RATES", "START_EDGE_MARGIN", "MAX_START_SPEED_FACTOR",
           "GRID_MIN_GAP", "MAX_SPEED_FACTOR", "_is_real"]
