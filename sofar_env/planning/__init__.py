"""High-level planning: the passing-side MIQP.

:class:`PassingSidePlanner` (module :mod:`.miqp`) with its parameters
(:mod:`.config`), side-constraint windows (:mod:`.clearance`), side hysteresis
(:mod:`.hysteresis`), problem data and cost (:mod:`.problem`) and DAQP solver
routes (:mod:`.solvers`).
"""

from sofar_env.planning.miqp import MIQPConfig, PassingSidePlanner, PlanResult

__all__ = ["MIQPConfig", "PassingSidePlanner", "PlanResult"]
