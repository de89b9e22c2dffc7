"""The configuration of the bug-compatible MPC (:class:`ReferenceNumerics`), defined in
:mod:`sofar_env.configs.refnum` (importable without the solvers) and re-exported here."""

from ...configs.refnum import PHANTOM_S, PHANTOM_SLOT_STEP, ReferenceNumerics

__all__ = ["ReferenceNumerics", "PHANTOM_S", "PHANTOM_SLOT_STEP"]
