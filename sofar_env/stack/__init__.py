"""Algorithm 1 of the paper: the hierarchical overtaking controller.

Per control step (:class:`OvertakingStack`, in :mod:`~sofar_env.stack.controller`):

1. transform the ego and the opponents into the Frenet frame of the raceline
   (opponent arc lengths become signed gaps to the ego);
2. predict the opponents along the track (:mod:`~sofar_env.stack.prediction`);
3. every ``miqp_interval``-th step, solve the passing-side MIQP for a lateral
   reference ``d*`` over the coarse horizon (:mod:`~sofar_env.stack.follow`);
4. take the barrier decay ``gamma`` from the caller (a policy, or fixed);
5. solve the MPC-DCBF with ``d*`` as the lateral reference and ``gamma``.

Additions to the paper's algorithm, each closing a failure mode seen in closed loop
(each can be switched off in :class:`StackConfig`; :func:`stack_preset` ``("paper")``
switches them all off):

* **Pass or follow** (:mod:`~sofar_env.stack.follow`): when no passing side of an
  opponent ahead is clear, the ego follows it (node positions held ``follow_gap``
  behind it, speed reference capped) instead of forcing the pass, with hysteresis and
  a reachability test for cars it is already alongside.
* **Pace-ratio opponent prediction** (:mod:`~sofar_env.stack.prediction`): opponents
  keep their pace ratio to the speed profile (they slow down for corners) instead of a
  constant speed.
* **Footprint-aware track edges** (:mod:`~sofar_env.stack.edges`): the planners' edges
  are the narrowest within the car's length, and the MPC's are tightened by how far
  the car's ends swing out at its heading error (measured against the edges' directions
  while a parked car is passed).
* **Consistent clearances** (:mod:`~sofar_env.stack.config`): the MIQP's side
  constraints use the braking-distance window of the MPC's barrier ellipse.

The stack never raises on numerical trouble: the planners return fallbacks,
which are counted (:attr:`OvertakingStack.counters`).
"""

from .config import STACK_PRESETS, StackConfig, stack_preset
from .controller import OvertakingStack, StackOutput

__all__ = ["StackConfig", "StackOutput", "OvertakingStack", "STACK_PRESETS", "stack_preset"]
