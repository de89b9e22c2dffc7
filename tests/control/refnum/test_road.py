"""The bug-compatible MPC on the synthetic road: the failure zones at both ends of gamma, and none without phantoms.

The same closed loop run with acados' SQP_RTI / FULL_CONDENSING_HPIPM failed at every solve from the second
on for gamma <= 0.05 at rho 0.3 and from the first for gamma >= 0.90 at rho 0.8, and never at mid gammas or
without phantoms: the failures here are HPIPM's (a too-short step), not a rule of ours.
"""

import pytest

from sofar_agents.evaluation.refnum_road import road_loop


@pytest.mark.parametrize("gamma, rho, phantoms, fails_from_start", [
    (0.05, 0.3, True, True),     # the phantom row binds while the ego accelerates: absorbing failure
    (0.07, 0.3, True, False),
    (0.5, 0.8, True, False),
    (0.89, 0.8, True, False),
    (0.90, 0.8, True, True),     # -gamma h of a phantom below the -1e9 bound
    (0.05, 0.3, False, False),   # no phantoms: no failure
    (0.95, 0.8, False, False),
])
def test_failures_are_where_the_phantoms_put_them(gamma, rho, phantoms, fails_from_start, cache_dir):
    out = road_loop(gamma, rho, steps=40, phantoms=phantoms, cache_dir=cache_dir)
    if fails_from_start:
        assert out.failures >= out.steps - 1 and out.qp_status[2] == out.failures  # every one a too-short step
    else:
        assert out.failures == 0 and out.qp_status[1] == out.steps  # the -1e9 bounds: the cap, accepted
