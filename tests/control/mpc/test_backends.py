"""QP backends: PIQP and OSQP solve the same QP, a solver failure is reported, not raised."""

import dataclasses

import numpy as np
import pytest
import scipy.sparse as sp

from sofar_env.control.mpc import MPCConfig, MPCDCBF
from sofar_env.control.mpc.backends import dcbf_margin, solve_qp
from sofar_env.control.mpc.layout import QPStructure

from .scenarios import make_stage


@pytest.fixture(scope="module")
def last_qp(cache_dir):
    """The last QP of a solve with an opponent close ahead (its structure holds matrices and vectors)."""
    mpc = MPCDCBF(MPCConfig(cache_dir=cache_dir))
    res = mpc.solve(np.array([0.0, 0.3, 0.0, 40.0, 0.0]), make_stage(), np.array([[20.0, 0.5, 35.0]]), 0.5)
    assert res.success and res.n_opponents == 1
    qs = [q for q in mpc._qp.values() if q.solver is not None and q.m == 1][-1]
    return mpc, qs


def _copy(qs: QPStructure, cfg: MPCConfig, lin) -> QPStructure:
    other = QPStructure(cfg, qs.m, qs.lat, qs.trk, lin.a_sparsity, lin.b_sparsity, lin.layout)
    other.A.data[:] = qs.A.data
    other.G.data[:] = qs.G.data
    for name in ("c_buf", "b_buf", "hl_buf", "hu_buf", "xl_buf", "xu_buf"):
        getattr(other, name)[:] = getattr(qs, name)
    return other


def test_piqp_and_osqp_solve_the_same_qp(last_qp):
    mpc, qs = last_qp
    piqp_qs = _copy(qs, mpc.config, mpc._lin)
    osqp_qs = _copy(qs, dataclasses.replace(mpc.config, qp_solver="osqp"), mpc._lin)
    z_p, it_p, msg_p = solve_qp(piqp_qs, piqp_qs.data(), mpc.config)
    z_o, it_o, msg_o = solve_qp(osqp_qs, osqp_qs.data(), mpc.config)
    assert msg_p == "solved" and msg_o == "solved" and it_p > 0 and it_o > 0
    # the first control (du_0) agrees to OSQP's accuracy
    np.testing.assert_allclose(z_o[:2], z_p[:2], atol=2e-2)
    # the DCBF margins: PIQP's own slack and h_u - G z agree at PIQP's solution
    hu, rows = piqp_qs.data()[3], piqp_qs.cbf_rows
    np.testing.assert_allclose(dcbf_margin(piqp_qs, z_p, hu), hu[rows] - (piqp_qs.G @ z_p)[rows], atol=1e-6)
    assert dcbf_margin(osqp_qs, z_o, hu).shape == (len(qs.cbf_rows),)


def test_the_compiled_dcbf_margin_is_scipys_product_to_the_bit(last_qp):
    """Without PIQP's own slacks, dcbf_margin is ``h_u - G z`` of the DCBF rows, the same bits as scipy's sparse
    product, on the closed loop's last QP and on random sparse data with a random row selection."""
    from sofar_env.control.mpc.backends import _csc_margin

    mpc, qs = last_qp
    osqp_qs = _copy(qs, dataclasses.replace(mpc.config, qp_solver="osqp"), mpc._lin)
    data = osqp_qs.data()
    z = np.random.default_rng(0).normal(size=qs.nz)
    hu, rows = data[3], qs.cbf_rows
    assert len(rows) and np.array_equal(dcbf_margin(osqp_qs, z, hu), hu[rows] - (osqp_qs.G @ z)[rows])
    rng = np.random.default_rng(1)
    for _ in range(20):
        g = sp.random(30, 25, density=0.3, format="csc", random_state=rng)
        z, hu = rng.normal(size=25) * 1e3, rng.normal(size=30)
        sel = rng.choice(30, size=rng.integers(1, 30), replace=False)
        assert np.array_equal(_csc_margin(g.data, g.indices, g.indptr, z, hu, sel), hu[sel] - (g @ z)[sel])


def test_solver_trouble_is_returned_not_raised(last_qp):
    mpc, qs = last_qp
    tight = _copy(qs, dataclasses.replace(mpc.config, qp_max_iter=1), mpc._lin)
    z, iters, message = solve_qp(tight, tight.data(), dataclasses.replace(mpc.config, qp_max_iter=1))
    assert z is None and iters == 1 and tight.solver is None and "status" in message


def test_osqp_backend_runs(cache_dir):
    mpc = MPCDCBF(MPCConfig(cache_dir=cache_dir, qp_solver="osqp"))
    res = mpc.solve(np.array([0.0, 0.3, 0.0, 40.0, 0.0]), make_stage(), np.array([[30.0, 3.0, 35.0]]), 0.5)
    assert res.u.shape == (2,) and res.status in ("solved", "fallback_brake")
