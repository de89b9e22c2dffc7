"""Parameters of the passing-side MIQP (:class:`MIQPConfig`), defined in :mod:`sofar_env.configs.miqp`
(importable without the solvers) and re-exported here."""

from ..configs.miqp import MIQPConfig

__all__ = ["MIQPConfig"]
