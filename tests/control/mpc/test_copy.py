"""Copies of the MPC (``copy.deepcopy``, pickle) continue to the bit like the original, without compiling."""

import copy
import pickle

import numpy as np
import pytest

from sofar_env.control.mpc import MPCConfig, MPCDCBF

from .scenarios import make_stage, plant_step


def _run(mpc: MPCDCBF, x: np.ndarray, steps: int, opp_s: float) -> tuple[list, np.ndarray]:
    """``steps`` closed-loop solves behind an opponent at 30 m/s; the results' controls and plans."""
    outs = []
    stage = make_stage()
    for k in range(steps):
        opp = np.array([[opp_s + (30.0 - x[3]) * 0.1 * k, 0.2, 30.0]])
        res = mpc.solve(x, stage, opp, 0.4)
        outs.append((res.u.copy(), res.x_pred.copy(), res.status, res.slack["barrier"]))
        x = plant_step(x, res.u, 0.1)
        x[0] = 0.0
    return outs, x


@pytest.mark.parametrize("how", ["deepcopy", "pickle"])
def test_copy_continues_bit_identically_without_compiling(cache_dir, how):
    mpc = MPCDCBF(MPCConfig(cache_dir=cache_dir))
    _, x = _run(mpc, np.array([0.0, 0.3, 0.0, 40.0, 0.0]), 8, 25.0)
    assert any(qs.solver_updates > 0 for qs in mpc._qp.values())  # the copy must replay the updates
    other = copy.deepcopy(mpc) if how == "deepcopy" else pickle.loads(pickle.dumps(mpc))
    assert other._lin.codegen_info.message == "loaded from cache"  # nothing compiled
    assert all(qs.solver is None for qs in other._qp.values())  # the solver handles are set up again
    mine, _ = _run(mpc, x.copy(), 12, 22.0)
    theirs, _ = _run(other, x.copy(), 12, 22.0)
    for a, b in zip(mine, theirs):
        np.testing.assert_array_equal(a[0], b[0])
        np.testing.assert_array_equal(a[1], b[1])
        assert a[2:] == b[2:]


def test_copy_has_its_own_buffers(cache_dir):
    mpc = MPCDCBF(MPCConfig(cache_dir=cache_dir))
    _run(mpc, np.array([0.0, 0.0, 0.0, 40.0, 0.0]), 2, 30.0)
    other = copy.deepcopy(mpc)
    lin, twin = mpc._lin, other._lin
    np.testing.assert_array_equal(lin.flat, twin.flat)
    assert not np.shares_memory(lin.flat, twin.flat)
    assert np.shares_memory(twin.a, twin.flat) and np.shares_memory(twin.dh, twin.flat)  # views rebuilt
    twin.evaluate(lin.x, lin.u[:-1], lin.kappa)  # the copy's compiled call writes into the copy's arrays
    np.testing.assert_array_equal(lin.f, twin.f)
