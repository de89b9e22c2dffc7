"""MPC with discrete-time control barrier functions (MPC-DCBF), solved as an SQP real-time iteration.

:class:`MPCDCBF` tracks a lateral and a speed reference along the track while a soft
discrete-time barrier condition ``h(x_{k+1}) >= (1 - gamma) h(x_k)`` keeps it away from
every opponent; ``gamma`` is the barrier decay chosen by the agent. The modules, in the
order the data flow:

* :mod:`.types` - :class:`MPCConfig`, :class:`MPCStageData` (per-stage track data),
  :class:`MPCResult`, and the check of a solve's arguments;
* :mod:`.model` - the optimal control problem, defined once: the CasADi stage function
  (RK4 step, lateral acceleration, barrier), its linearisation, the cost and bound data
  and the opponent prediction and selection (its docstring states the problem);
* :mod:`.warmstart` - the initial guess: the previous plan shifted in time, or a cold guess;
* :mod:`.linearisation` - the compiled stage Jacobians at all stages, evaluated into numpy arrays;
* :mod:`.layout` - the QP's variables and rows, its fixed sparsity and how it is filled;
* :mod:`.backends` - the QP solvers (PIQP, OSQP; DAQP on the condensed QP, :mod:`.condensed`);
* :mod:`.rti` - :class:`MPCDCBF`, the real-time iteration and its failure handling;
* :mod:`.reference` - the same NLP solved to convergence with IPOPT
  (:meth:`MPCDCBF.solve_converged`), for validation.
"""

from .rti import MPCDCBF
from .types import STATUS_FALLBACK_BRAKE, STATUS_FALLBACK_SHIFT, STATUS_SOLVED, MPCConfig, MPCResult, MPCStageData

__all__ = ["MPCConfig", "MPCStageData", "MPCResult", "MPCDCBF", "STATUS_SOLVED", "STATUS_FALLBACK_SHIFT",
           "STATUS_FALLBACK_BRAKE"]
