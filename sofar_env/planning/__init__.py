"""High-level planning: the passing-side MIQP."""

from sofar_env.planning.miqp import MIQPConfig, PassingSidePlanner, PlanResult

__all__ = ["MIQPConfig", "PassingSidePlanner", "PlanResult"]
