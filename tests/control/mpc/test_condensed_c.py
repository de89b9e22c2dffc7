"""The DAQP backend's compiled route (:func:`sofar_env.planning.daqp_c.soft_solve` and
:func:`sofar_env.control.mpc.condensed._solve_compact`) against the :class:`daqp.Model` route it replaces,
bit for bit: per-row soft weights, the rows with both bounds infinite left out, DAQP's workspace set up and
freed in one call."""

from __future__ import annotations

import numpy as np
import pytest

import daqp
from sofar_env.control.mpc import MPCConfig, condensed
from sofar_env.planning import daqp_c

pytestmark = pytest.mark.skipif(not daqp_c.SOFT_AVAILABLE, reason="another daqp than the pinned one: no C route")

def _model_solve(H, f, A, bu, bl, sense, rho, w, settings=None):
    model = daqp.Model()
    flag, _ = model.setup(H, f, A, bu, bl, sense.copy())
    assert flag >= 0
    if settings:
        model.settings = settings
    model.soft_weights(rho_l=rho, rho_u=rho, w_l=w, w_u=w)
    x, _, flag, info = model.solve()
    return np.asarray(x), flag, info["iterations"]


def _random_soft_qp(rng, n, ms, ma, inf_rows=0):
    L = rng.standard_normal((n, n))
    H = L @ L.T + 0.5 * np.eye(n)
    f = 3.0 * rng.standard_normal(n)
    A = rng.standard_normal((ma + inf_rows, n))
    bu = np.concatenate([rng.uniform(0.2, 2.0, ms), rng.uniform(-0.5, 1.0, ma), np.full(inf_rows, np.inf)])
    bl = np.concatenate([-rng.uniform(0.2, 2.0, ms), bu[ms:ms + ma] - rng.uniform(0.0, 2.0, ma),
                         np.full(inf_rows, -np.inf)])
    order = np.concatenate([np.arange(ms), ms + rng.permutation(ma + inf_rows)])  # infinite rows anywhere
    A = A[order[ms:] - ms]
    bu, bl = bu[order], bl[order]
    m = ms + ma + inf_rows
    sense = np.where(rng.random(m) < 0.5, 8, 0).astype(np.int32)
    sense[:ms] = 0
    rho = np.where(sense == 8, rng.uniform(1e-3, 1.0, m), 0.0)
    w = np.where(sense == 8, rng.uniform(0.0, 2.0, m), 0.0)
    return H, f, A, bu, bl, sense, rho, w


def test_soft_solve_is_daqp_model_to_the_bit():
    """Random QPs with simple bounds, general rows and soft rows of their own weights (many violated at the
    optimum): the kernel returns the Model's solution, exit flag and iterations, leaves ``sense`` as given and
    the workspace zeroed, and its settings record is used (a tighter iteration limit changes the outcome)."""
    rng = np.random.default_rng(11)
    ws = daqp_c.Workspace()
    flags = set()
    for trial in range(80):
        n, ms, ma = int(rng.integers(2, 9)), int(rng.integers(0, 4)), int(rng.integers(1, 9))
        ms = min(ms, n)
        H, f, A, bu, bl, sense, rho, w = _random_soft_qp(rng, n, ms, ma)
        x_ref, flag_ref, it_ref = _model_solve(H, f, A, bu, bl, sense, rho, w)
        given = sense.copy()
        setup, flag, iters = daqp_c.soft_solve(H, f, A, bu, bl, sense, rho, w, ws.records, ws.reserve(n, len(bu)),
                                               ws.work, daqp_c.SETTINGS_SLOT)
        assert setup == 1 and flag == flag_ref and iters == it_ref
        np.testing.assert_array_equal(ws.buffers[0][:n], x_ref)
        np.testing.assert_array_equal(sense, given)
        assert not ws.work.any()
        flags.add(flag)
    assert flags >= {1, 2}  # optimal and soft-optimal both covered
    # the settings record is DAQP's: an iteration limit of 1 stops where the Model with that limit stops
    H, f, A, bu, bl, sense, rho, w = _random_soft_qp(np.random.default_rng(3), 6, 0, 8)
    ws.records[1][0]["iter_limit"] = 1
    x_ref, flag_ref, _ = _model_solve(H, f, A, bu, bl, sense, rho, w, settings={"iter_limit": 1})
    _, flag, _ = daqp_c.soft_solve(H, f, A, bu, bl, sense, rho, w, ws.records, ws.reserve(6, 8), ws.work,
                                   daqp_c.SETTINGS_SLOT)
    assert flag == flag_ref == -4  # DAQP's iteration limit


def test_a_failed_setup_is_reported_and_frees_the_workspace():
    """A Hessian that is not positive definite (and no regularisation): the setup's negative flag comes back,
    nothing is solved, and the workspace is zeroed for the next call, which then solves."""
    ws = daqp_c.Workspace()
    ws.records[1][0]["eps_prox"] = 0.0  # no automatic regularisation: an indefinite H fails the factorization
    H = np.array([[1.0, 0.0], [0.0, -1.0]])
    f = np.zeros(2)
    A = np.array([[1.0, 1.0]])
    bu, bl = np.array([1.0]), np.array([-1.0])
    sense, rho, w = np.zeros(1, dtype=np.int32), np.zeros(1), np.zeros(1)
    setup, _, _ = daqp_c.soft_solve(H, f, A, bu, bl, sense, rho, w, ws.records, ws.reserve(2, 1), ws.work,
                                    daqp_c.SETTINGS_SLOT)
    assert setup < 0 and not ws.work.any()
    setup, flag, _ = daqp_c.soft_solve(np.eye(2), np.ones(2), A, bu, bl, sense, rho, w, ws.records,
                                       ws.reserve(2, 1), ws.work, daqp_c.SETTINGS_SLOT)
    assert setup == 1 and flag == 1
    np.testing.assert_array_equal(ws.buffers[0][:2], [-0.5, -0.5])


def test_rows_with_both_bounds_infinite_change_no_bit():
    """The compact kernel leaves out rows bounded by (-inf, inf) wherever they sit; the solution is the Model's
    on the full problem, to the bit."""
    rng = np.random.default_rng(5)
    for _ in range(40):
        n, ms, ma, ninf = 5, 5, int(rng.integers(1, 7)), int(rng.integers(1, 10))
        H, f, A, bu, bl, sense, rho, w = _random_soft_qp(rng, n, ms, ma, inf_rows=ninf)
        x_ref, flag_ref, it_ref = _model_solve(H, f, A, bu, bl, sense, rho, w)
        m = len(bu)
        ws = daqp_c.Workspace(n, m)
        compact = (np.zeros((m - n, n)), np.empty(m), np.empty(m), np.empty(m, dtype=np.int32), np.empty(m),
                   np.empty(m))
        setup, flag, iters = condensed._solve_compact(H, f, A, bu, bl, sense, rho, w, compact, ws.records,
                                                      ws.buffers, ws.work, daqp_c.SETTINGS_SLOT)
        assert (setup, flag, iters) == (1, flag_ref, it_ref)
        np.testing.assert_array_equal(ws.buffers[0][:n], x_ref)


@pytest.mark.parametrize("track_rows", ["reference", "ends"])
def test_the_backend_routes_agree_to_the_bit_on_closed_loop_qps(bench, cache_dir, track_rows):
    """The QPs of a closed loop (the ring road, soft DCBF, lateral and track rows; with ``"ends"`` the explicit
    slack): :meth:`CondensedDAQP.solve` by the compiled route returns the Model route's z, iterations and
    message, to the bit, and drops about half of the condensed rows or more as unbounded."""
    cfg = MPCConfig(cache_dir=cache_dir, track_rows=track_rows)
    qps = bench.record_qps(steps=40, cfg=cfg)
    routes = {}
    dropped = []
    for qs, data in qps:
        key = (qs.m, qs.lat, qs.trk)
        if key not in routes:
            native, model = condensed.CondensedDAQP(qs), condensed.CondensedDAQP(qs)
            model.native = None
            routes[key] = (native, model)
        native, model = routes[key]
        z_n, it_n, msg_n = native.solve(qs, data)
        z_m, it_m, msg_m = model.solve(qs, data)
        assert z_n is not None and msg_n == msg_m == "solved" and it_n == it_m
        np.testing.assert_array_equal(z_n, z_m)
        _, _, _, bu, bl, *_ = native.condense(qs, data)
        dropped.append(np.mean(np.isinf(bu[native.nv:]) & np.isinf(bl[native.nv:])))
    assert any(model.model is not None for _, model in routes.values())
    assert np.median(dropped) > 0.4
