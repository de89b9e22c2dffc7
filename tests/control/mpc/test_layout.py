"""The QP layout: its matrices are the linearised constraints of the problem, entry by entry."""

import numpy as np
import pytest

from sofar_env.control.mpc import MPCConfig
from sofar_env.control.mpc.layout import N_FIXED, QPStructure
from sofar_env.control.mpc.linearisation import StageLinearisation
from sofar_env.vehicle import AV21


@pytest.fixture(scope="module")
def linearised(cache_dir):
    cfg = MPCConfig(cache_dir=cache_dir, max_opponents=3)
    t = cfg.time_grid()
    lin = StageLinearisation(cfg, AV21, np.diff(t))
    rng = np.random.default_rng(7)
    xbar = np.column_stack([40.0 * t, rng.uniform(-1, 1, len(t)), rng.uniform(-0.02, 0.02, len(t)),
                            40.0 + rng.uniform(-1, 1, len(t)), rng.uniform(-0.05, 0.05, len(t))])
    ubar = np.column_stack([rng.uniform(-3, 2, cfg.horizon), rng.uniform(-0.2, 0.2, cfg.horizon)])
    lin.set_opponents(np.array([[30.0, 1.0, 35.0], [-10.0, -3.0, 42.0], [70.0, 0.0, 30.0]]), t)
    lin.evaluate(xbar, ubar, rng.uniform(-0.01, 0.01, len(t)))
    return cfg, lin


def _dense(lin, k, which):
    rows, cols = lin.a_sparsity if which == "A" else lin.b_sparsity
    mat = np.zeros((5, 5 if which == "A" else 2))
    mat[rows, cols] = (lin.a if which == "A" else lin.b)[k]
    return mat


@pytest.mark.parametrize("lat,trk", [(True, True), (False, True), (True, False), (False, False)])
def test_matrices_are_the_linearised_constraints(linearised, lat, trk):
    cfg, lin = linearised
    n_h = cfg.horizon
    act = np.array([2, 0])  # QP slot 0 is stage-function slot 2, QP slot 1 is slot 0
    gamma = 0.3
    qs = QPStructure(cfg, len(act), lat, trk, lin.a_sparsity, lin.b_sparsity, lin.layout)
    qs.fill_matrices(lin.flat, act, gamma)
    assert qs.nb == N_FIXED + lat + trk + len(act) and qs.A.shape == (5 * n_h, qs.nz)
    z = np.random.default_rng(8).normal(size=qs.nz)
    zz = z.reshape(n_h, qs.nb)
    du, dx = zz[:, 0:2], np.vstack([np.zeros(5), zz[:, 2:7]])  # dx_0 = 0: x_0 is fixed
    # equality rows: dx_{k+1} - A_k dx_k - B_k du_k
    expected = [dx[k + 1] - _dense(lin, k, "A") @ dx[k] - _dense(lin, k, "B") @ du[k] for k in range(n_h)]
    np.testing.assert_allclose(qs.A @ z, np.concatenate(expected), rtol=1e-12, atol=1e-12)
    # inequality rows, per stage: [lat up, lat low], [trk up, trk low], DCBF of each QP slot
    scale = qs.slack_scale
    gz = (qs.G @ z).reshape(n_h, qs.nr)
    for k in range(n_h):
        rows = []
        col = N_FIXED
        if lat:
            d_alat = lin.dalat[k + 1] @ dx[k + 1, 3:5]
            rows += [d_alat - scale[0] * zz[k, col], d_alat + scale[0] * zz[k, col]]
            col += 1
        if trk:
            rows += [dx[k + 1, 1] - scale[int(lat)] * zz[k, col], dx[k + 1, 1] + scale[int(lat)] * zz[k, col]]
            col += 1
        for i, slot in enumerate(act):
            snv = [0, 1, 3]
            rows.append((1.0 - gamma) * lin.dh[k, slot] @ dx[k, snv] - lin.dh[k + 1, slot] @ dx[k + 1, snv]
                        - scale[-1] * zz[k, col + i])
        np.testing.assert_allclose(gz[k], rows, rtol=1e-12, atol=1e-12)


def test_cost_is_the_scaled_quadratic_of_the_problem(linearised):
    cfg, lin = linearised
    qs = QPStructure(cfg, 1, True, True, lin.a_sparsity, lin.b_sparsity, lin.layout)
    p_diag = qs.P.diagonal().reshape(cfg.horizon, qs.nb)
    np.testing.assert_array_equal(p_diag[:, :N_FIXED], np.tile(2.0 * np.r_[cfg.r, cfg.q], (cfg.horizon, 1)))
    np.testing.assert_array_equal(p_diag[:, N_FIXED:], 1.0)  # slacks scaled by sqrt(Z)
    np.testing.assert_allclose(qs.slack_scale ** -2, [cfg.lat_acc_slack[1], cfg.track_slack[1],
                                                      cfg.barrier_slack[1]])
    # the L1 weight of a scaled slack: z * sigma = (z / sqrt(Z)) * sigma~
    np.testing.assert_allclose(qs.c_buf[0, N_FIXED:], np.array([4e3, 3.5e4, 9e4]) * qs.slack_scale)
