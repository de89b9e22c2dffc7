"""The bug-compatible MPC: the slots it fills, the failure it reproduces, and that it is never a default."""

import math

import numpy as np
import pytest

from sofar_env.control.mpc import MPCConfig
from sofar_env.control.refnum import ReferenceNumerics, ReferenceNumericsMPC, slot_rows
from sofar_env.control.refnum.config import PHANTOM_S
from sofar_env.stack import STACK_PRESETS, StackConfig, stack_preset

from ..mpc.scenarios import make_stage

GRID = MPCConfig(first_step=0.075)


def test_slot_rows_fill_every_slot_as_the_reference_does():
    rn = ReferenceNumerics()
    # v = 40 m/s: the target line is 150 x 4 m = 600 m long
    opp = np.array([[-5.0, 1.0, 30.0], [10.0, -2.0, 35.0], [700.0, 0.5, 50.0]])
    rows, real = slot_rows(opp, 40.0, rn, spacing=1.0)
    np.testing.assert_array_equal(rows, [[10.0, -2.0, 35.0], [PHANTOM_S, 0.0, 30.0], [PHANTOM_S, 0.0, 50.0],
                                         [PHANTOM_S + 300.0, 0.0, 0.0]])
    np.testing.assert_array_equal(real, [True, False, False, False])
    # a longer line (Monza's spacing) reaches the car 700 m ahead
    rows, real = slot_rows(opp, 40.0, rn, spacing=1.5)
    assert real.tolist() == [True, True, False, False] and rows[1, 0] == 700.0


def _solve_repeatedly(numerics, gamma, opp, v=40.0, v_ref=40.0, steps=3):
    mpc = ReferenceNumericsMPC(GRID, numerics)
    return [mpc.solve(np.array([0.0, 0.0, 0.0, v, 0.0]), make_stage(v_ref=v_ref), opp, gamma) for _ in range(steps)], mpc


# opponents 50 m behind and 2 km ahead, both faster than the ego: two phantoms with h of about 1.1e9
FAST_PHANTOMS = np.array([[-50.0, 0.0, 45.0], [2000.0, 1.0, 45.0]])


@pytest.mark.parametrize("gamma, fails", [(0.5, False), (0.89, False), (0.91, True), (0.95, True)])
def test_phantom_rows_break_the_solve_above_gamma_0_9(gamma, fails):
    """-gamma h of a phantom passes the rows' lower bound -1e9 for gamma > 1e9 / h = 0.90: HPIPM stops on a
    too-short step, and the command is throttle 0 with the steering towards 0."""
    results, mpc = _solve_repeatedly(ReferenceNumerics(), gamma, FAST_PHANTOMS)
    assert all((not r.success) == fails for r in results)
    if fails:
        assert mpc.qp_status_counts[2] == len(results) and mpc.n_failures == len(results)
        assert all(r.status == "fallback_zero" and r.u[0] == 0.0 for r in results)
    else:
        assert mpc.qp_status_counts[1] == len(results)  # the -1e9 bounds: the iteration cap, accepted


def test_without_phantoms_the_same_solve_succeeds():
    results, mpc = _solve_repeatedly(ReferenceNumerics(phantoms=False), 0.95, FAST_PHANTOMS)
    assert all(r.success for r in results) and mpc.n_failures == 0


def test_counting_the_iteration_cap_as_failure_fails_every_solve():
    """Every QP of the reference hits the cap (the -1e9 bounds): reading the cap as failure would fail all."""
    results, _ = _solve_repeatedly(ReferenceNumerics(max_iter_is_failure=True), 0.5, FAST_PHANTOMS)
    assert not any(r.success for r in results)


def test_a_solved_step_accelerates_towards_the_speed_reference():
    results, _ = _solve_repeatedly(ReferenceNumerics(), 0.5, np.zeros((0, 3)), v=30.0, v_ref=40.0)
    assert all(r.success for r in results)
    assert results[0].u[0] == pytest.approx(3.0)  # full throttle 10 m/s below the reference
    assert math.isinf(results[0].barrier_min)


def test_the_grid_must_be_uniform():
    with pytest.raises(ValueError, match="uniform"):
        ReferenceNumericsMPC(MPCConfig(), ReferenceNumerics())


@pytest.mark.parametrize("bad", [{"phantoms": "yes"}, {"slots": 0}, {"a0": -1.0}, {"lower_bound": 1.0},
                                 {"track_margin": float("nan")}, {"qp": None}])
def test_numerics_are_validated(bad):
    with pytest.raises(ValueError):
        ReferenceNumerics(**bad)


def test_only_the_labelled_presets_use_it():
    assert StackConfig().reference_numerics is None
    users = [p for p in STACK_PRESETS if stack_preset(p).reference_numerics is not None]
    assert users == ["reference-numerics", "reference-numerics-no-phantoms"]
    assert stack_preset("reference-numerics").reference_numerics.phantoms
    assert not stack_preset("reference-numerics-no-phantoms").reference_numerics.phantoms


@pytest.mark.parametrize("stack, gamma, expect_failures", [
    ("reference-numerics", 0.95, True),
    ("reference-numerics", 0.5, False),
    ("reference-numerics-no-phantoms", 0.95, False),
])
def test_closed_loop_the_failure_needs_phantoms_and_a_large_gamma(stack, gamma, expect_failures):
    """Laguna Seca at rho 0.8 (opponents as fast as the ego): 3 s of racing."""
    import gymnasium as gym

    import sofar_env  # noqa: F401  (registers the ids)

    env = gym.make("SOfAR-LagunaSeca-v0", config={"stack": stack, "rho": 0.8, "race": {"duration": 3.0}})
    env.reset(seed=4)
    info = {}
    for _ in range(30):
        _, _, term, trunc, info = env.step(np.array([gamma], dtype=np.float32))
        if term or trunc:
            break
    assert (info["mpc_failures"] > 0) == expect_failures
    env.close()


def test_condensing_reproduces_the_linear_rollout():
    from sofar_env.control.refnum import condense

    rng = np.random.default_rng(3)
    n, nx, nu = 6, 5, 2
    A, B = rng.normal(size=(n, nx, nx)) * 0.5, rng.normal(size=(n, nx, nu))
    f, x_next, dx0, du = rng.normal(size=(n, nx)), rng.normal(size=(n, nx)), rng.normal(size=nx), rng.normal(size=n * nu)
    G, xoff = condense(A, B, f, x_next, dx0)
    dx = dx0
    for k in range(n):
        np.testing.assert_allclose(xoff[k] + G[k] @ du, dx, rtol=1e-12, atol=1e-12)
        dx = A[k] @ dx + B[k] @ du[nu * k:nu * (k + 1)] + f[k] - x_next[k]
    np.testing.assert_allclose(xoff[n] + G[n] @ du, dx, rtol=1e-12, atol=1e-12)
