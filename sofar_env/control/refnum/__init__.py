"""A **bug-compatible** MPC: the paper's reference implementation, numerical defects included.

Never a default: it exists to explain a published number. The paper's Table I has the fixed barrier
decays gamma = 0.05 and 0.95 collapsing (0 % success on the road courses) while mid gammas do better;
the project's own controllers (:mod:`sofar_env.control.mpc`) do not show that. The hypothesis
reproduced here is a numerical artefact of the reference code, not a property of the method:

* **Phantom opponents.** The OCP has 4 opponent slots, always filled: an opponent that does not
  project onto the 151-point target line (behind the ego, or beyond the line) is placed at
  s = 99999 m with its real speed, an empty slot at 99999 + 100 i with speed 0. The barrier of such a
  row is of order 1e8-1e9.
* **Soft rows bounded at -1e9.** The DCBF rows ``(1 - gamma) h_k - h_{k+1} <= 0`` (and the track rows)
  are soft with a lower bound of -1e9, which a phantom row can reach: ``-gamma h`` passes -1e9 for
  gamma above about 0.90 when the ego is not faster than the phantom. For gamma below about 0.056 the
  upper side binds while the ego accelerates towards a phantom it is faster than (the barrier's
  semi-axis grows with the closing speed), a row with coefficients of order 1e8.
* **HPIPM's iteration cap.** The QP is solved by HPIPM's dense interior-point method with acados'
  options (50 iterations); acados' SQP_RTI applies the last iterate when the cap is reached and
  reports failure only for a too-short step or a NaN.
* **Zero command on failure.** The reference simulator then applies throttle 0 and steering 0, and
  keeps the iterate, which keeps the failing condition alive.
* **No DCBF on the first transition** (acados v0.4.3 puts path constraints on nodes 1..N-1 only).

:class:`ReferenceNumericsMPC` runs the same HPIPM (the build that ships with CasADi, :mod:`.hpipm`) on
the same condensed QP with the same options; :class:`ReferenceNumerics` switches each defect off, one at
a time, so a sweep can attribute an effect to its cause. Why HPIPM from CasADi's wheel rather than acados
or a solver of ours, and how it was checked against acados: ``docs/decisions/reference-numerics-solver.md``.
Use it through
``stack_preset("reference-numerics")`` (``stack="reference-numerics"`` in the environments).
"""

from .config import ReferenceNumerics
from .controller import STATUS_ZERO_COMMAND, ReferenceNumericsMPC, condense, slot_rows
from .hpipm import DenseQP, HPIPMOptions, HPIPMUnavailable

__all__ = ["ReferenceNumerics", "ReferenceNumericsMPC", "STATUS_ZERO_COMMAND", "slot_rows", "condense", "DenseQP",
           "HPIPMOptions", "HPIPMUnavailable"]
