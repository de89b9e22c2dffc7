"""Low-level control: velocity-aware barrier and the MPC-DCBF (SQP real-time iteration)."""

from .barrier import BarrierParams, barrier, casadi_barrier
from .codegen import CodegenInfo, compile_function
from .mpc import MPCConfig, MPCDCBF, MPCResult, MPCStageData

__all__ = [
    "BarrierParams",
    "barrier",
    "casadi_barrier",
    "CodegenInfo",
    "compile_function",
    "MPCConfig",
    "MPCDCBF",
    "MPCResult",
    "MPCStageData",
]
