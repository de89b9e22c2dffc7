"""The compiled QP assembly (sofar_env.control.mpc.assembly) against the plain numpy form, bit for bit."""

import numpy as np
import pytest

from sofar_env.control.mpc import MPCConfig
from sofar_env.control.mpc.assembly import STATUS_INCONSISTENT, STATUS_NONFINITE, STATUS_OK, assemble
from sofar_env.control.mpc.layout import N_FIXED, QPStructure
from sofar_env.control.mpc.linearisation import StageLinearisation
from sofar_env.control.mpc.model import stage_reference, track_limits, variable_box
from sofar_env.vehicle import AV21

BOX_DIST = np.array([2.0, 0.15, np.inf, np.inf, np.inf, 5.0, 0.08])


@pytest.fixture(scope="module")
def linearised(cache_dir):
    cfg = MPCConfig(cache_dir=cache_dir, max_opponents=3)
    t = cfg.time_grid()
    lin = StageLinearisation(cfg, AV21, np.diff(t))
    rng = np.random.default_rng(11)
    xbar = np.column_stack([40.0 * t, rng.uniform(-1, 1, len(t)), rng.uniform(-0.02, 0.02, len(t)),
                            40.0 + rng.uniform(-1, 1, len(t)), rng.uniform(-0.05, 0.05, len(t))])
    ubar = np.column_stack([rng.uniform(-3, 2, cfg.horizon), rng.uniform(-0.2, 0.2, cfg.horizon)])
    lin.set_opponents(np.array([[30.0, 1.0, 35.0], [-10.0, -3.0, 42.0], [70.0, 0.0, 30.0]]), t)
    kappa = rng.uniform(-0.01, 0.01, len(t))
    lin.evaluate(xbar, ubar, kappa)
    arrays = np.vstack([kappa, rng.uniform(-1, 1, len(t)), 45.0 + rng.uniform(-5, 5, len(t)),
                        np.full(len(t), -6.0), np.full(len(t), 6.0)])
    return cfg, lin, xbar, ubar, arrays


def numpy_form(qs, lin, xbar, ubar, arrays, gamma, box, act, trk_lo, trk_hi, box_dist, lat_acc_max):
    """The assembly as numpy expressions: (c, b, hl, hu, xl, xu, A values, G values, box lo, box hi)."""
    c, b = qs.c_buf.copy(), qs.b_buf.copy()
    hl, hu, xl, xu = qs.hl_buf.copy(), qs.hu_buf.copy(), qs.xl_buf.copy(), qs.xu_buf.copy()
    x7 = np.hstack([ubar, xbar[1:]])
    c[:, :N_FIXED] = qs.w7 * (x7 - stage_reference(arrays))
    a_val = lin.flat[qs.a_src] * qs.a_fac
    offset = np.zeros(qs.m + 1, dtype=np.int64)
    offset[: qs.m] = 3 * act
    g_val = lin.flat[qs.g_src + offset[qs.g_slot]] * (qs.g_fac + (1.0 - gamma) * qs.g_gam)
    b[:] = lin.f[:-1] - xbar[1:]
    if qs.lat:
        hu[:, qs.row_lat] = lat_acc_max - lin.alat[1:]
        hl[:, qs.row_lat + 1] = -lat_acc_max - lin.alat[1:]
    if qs.trk:
        hu[:, qs.row_trk] = trk_hi
        hl[:, qs.row_trk + 1] = trk_lo
    if qs.m:
        h = lin.h[:, act]
        hu[:, qs.row_cbf:] = h[1:] - (1.0 - gamma) * h[:-1]
    lo, hi = box[0] - x7, box[1] - x7
    xl[:, :N_FIXED] = lo if box_dist is None else np.where(lo < -box_dist, -np.inf, lo)
    xu[:, :N_FIXED] = hi if box_dist is None else np.where(hi > box_dist, np.inf, hi)
    return c, b, hl, hu, xl, xu, a_val, g_val, lo, hi


def run_kernel(qs, lin, xbar, ubar, arrays, gamma, box, act, trk_lo, trk_hi, box_dist, lat_acc_max):
    n = ubar.shape[0]
    lo_out, hi_out = np.empty((n, N_FIXED)), np.empty((n, N_FIXED))
    status = assemble((xbar, ubar), (arrays[1, 1:], arrays[2, 1:]), qs.w7,
                      (box[0], box[1], box_dist is not None, BOX_DIST if box_dist is None else box_dist),
                      (lin.flat, lin.f, lin.alat, lin.h), (qs.a_src, qs.a_fac, qs.A.data),
                      (qs.g_src, qs.g_slot, qs.g_gam, qs.g_fac, qs.G.data), (act, gamma),
                      (qs.lat, qs.row_lat, lat_acc_max, qs.trk, qs.row_trk, trk_lo, trk_hi, qs.row_cbf),
                      (qs.c_buf, qs.b_buf, qs.hl_buf, qs.hu_buf, qs.xl_buf, qs.xu_buf), (lo_out, hi_out))
    return status, (qs.c_buf, qs.b_buf, qs.hl_buf, qs.hu_buf, qs.xl_buf, qs.xu_buf, qs.A.data, qs.G.data,
                    lo_out, hi_out)


@pytest.mark.parametrize("m, lat, trk, dist", [(0, True, True, False), (2, True, True, False),
                                               (3, False, True, True), (1, True, False, True),
                                               (2, False, False, True)])
@pytest.mark.parametrize("gamma", [0.05, 0.37, 1.0])
def test_assembly_equals_the_numpy_form_to_the_bit(linearised, m, lat, trk, dist, gamma):
    cfg, lin, xbar, ubar, arrays = linearised
    qs = QPStructure(cfg, m, lat, trk, lin.a_sparsity, lin.b_sparsity, lin.layout)
    act = np.array([2, 0, 1][:m], dtype=np.intp)
    box = variable_box(AV21)
    lo, hi = track_limits(cfg, arrays)
    trk_lo, trk_hi = lo - xbar[1:, 1], hi - xbar[1:, 1]
    box_dist = BOX_DIST.copy() if dist else None
    args = (qs, lin, xbar, ubar, arrays, gamma, box, act, trk_lo, trk_hi, box_dist, AV21.lat_acc_max)
    want = numpy_form(*args)
    status, got = run_kernel(*args)
    assert status == STATUS_OK
    for name, g, w in zip(("c", "b", "hl", "hu", "xl", "xu", "A", "G", "box lo", "box hi"), got, want):
        np.testing.assert_array_equal(g, w, err_msg=name)


@pytest.mark.parametrize("where", ["xbar", "ubar", "alat", "h_active", "flat_a"])
def test_a_non_finite_input_is_reported(linearised, where):
    cfg, lin, xbar, ubar, arrays = linearised
    xbar, ubar = xbar.copy(), ubar.copy()
    kept = lin.flat.copy(), lin.alat.copy(), lin.h.copy()
    qs = QPStructure(cfg, 2, True, True, lin.a_sparsity, lin.b_sparsity, lin.layout)
    act = np.array([0, 2], dtype=np.intp)
    try:
        if where == "xbar":
            xbar[4, 3] = np.nan
        elif where == "ubar":
            ubar[2, 0] = np.inf
        elif where == "alat":
            lin.alat[0] = np.nan  # stage 0: not in any bound, still checked
        elif where == "h_active":
            lin.h[-1, 2] = -np.inf
        else:
            lin.flat[qs.a_src[5]] = np.nan
        lo, hi = track_limits(cfg, arrays)
        status, _ = run_kernel(qs, lin, xbar, ubar, arrays, 0.5, variable_box(AV21), act, lo - xbar[1:, 1],
                               hi - xbar[1:, 1], None, AV21.lat_acc_max)
        assert status == STATUS_NONFINITE
    finally:
        lin.flat[:], lin.alat[:], lin.h[:] = kept


def test_an_inactive_slot_may_be_non_finite_and_crossed_bounds_are_reported(linearised):
    cfg, lin, xbar, ubar, arrays = linearised
    kept = lin.h.copy()
    qs = QPStructure(cfg, 1, True, True, lin.a_sparsity, lin.b_sparsity, lin.layout)
    lo, hi = track_limits(cfg, arrays)
    try:
        lin.h[:, 1] = np.nan  # slot 1 has no QP rows
        args = (qs, lin, xbar, ubar, arrays, 0.5, variable_box(AV21), np.array([0], dtype=np.intp),
                lo - xbar[1:, 1], hi - xbar[1:, 1], None, AV21.lat_acc_max)
        assert run_kernel(*args)[0] == STATUS_OK
        box = variable_box(AV21)
        crossed = (box[0].copy(), box[1].copy())
        crossed[0][0] = crossed[1][0] + 1.0  # a_min above a_max
        args = args[:6] + (crossed,) + args[7:]
        assert run_kernel(*args)[0] == STATUS_INCONSISTENT
    finally:
        lin.h[:] = kept


@pytest.mark.parametrize("scale", [1e-7, 0.05, 0.3, 3.0])
def test_violated_rows_equal_the_numpy_form(linearised, scale):
    """The check of the left-out rows against its numpy expressions, on steps that violate nothing, some or
    all of them."""
    from sofar_env.control.mpc.assembly import violated_rows

    cfg, lin, xbar, ubar, arrays = linearised
    rng = np.random.default_rng(int(scale * 1e7) % 2**32)
    n = cfg.horizon
    zz = rng.normal(size=(n, N_FIXED + 3)) * scale
    box = variable_box(AV21)
    x7 = np.hstack([ubar, xbar[1:]])
    box_lo, box_hi = box[0] - x7, box[1] - x7
    lo, hi = track_limits(cfg, arrays)
    trk_lo, trk_hi = lo - xbar[1:, 1], np.full(n, 0.1)  # the upper track bound 0.1 m from the iterate
    tol = 1e-6
    lat_max = 1.01 * np.abs(lin.alat).max()
    mask = np.empty(N_FIXED, dtype=np.bool_)
    lat, trk, any_box = violated_rows(zz, True, lin.dalat, lin.alat, lat_max, True, trk_lo, trk_hi, box_lo,
                                      box_hi, True, tol, mask)
    alat = np.abs((lin.dalat[1:] * zz[:, 5:7]).sum(axis=1) + lin.alat[1:])
    assert lat == (alat.max() > lat_max + tol)
    assert trk == (max((zz[:, 3] - trk_hi).max(), (trk_lo - zz[:, 3]).max()) > tol)
    dz = zz[:, :N_FIXED]
    worst = np.maximum((box_lo - dz).max(axis=0), (dz - box_hi).max(axis=0))
    assert any_box == (worst.max() > tol)
    np.testing.assert_array_equal(mask, worst > tol)
    assert violated_rows(zz, False, lin.dalat, lin.alat, lat_max, False, trk_lo, trk_hi, box_lo, box_hi, False,
                         tol, mask) == (False, False, False)


def test_the_compiled_track_rows_are_the_numpy_form():
    from sofar_env.control.mpc.assembly import track_rows

    rng = np.random.default_rng(2)
    cfg = MPCConfig()
    n = cfg.horizon
    for trial in range(300):
        arrays = rng.normal(size=(5, n + 1)) * 2.0
        arrays[3] -= 6.0
        arrays[4] += 6.0
        xbar = rng.normal(size=(n + 1, 5)) * 3.0
        alat = rng.normal(size=n + 1) * 8.0
        if trial % 5 == 0:
            alat[rng.integers(0, n + 1)] = np.nan
        if trial % 7 == 0:
            xbar[rng.integers(0, n + 1), 1] = np.nan
        lo, hi = track_limits(cfg, arrays)
        want_lo, want_hi = lo - xbar[1:, 1], hi - xbar[1:, 1]
        want_lat = bool(np.abs(alat[1:]).max() > AV21.lat_acc_max - 3.0)
        want_trk = bool(want_hi.min() < 0.5 or want_lo.max() > -0.5)
        got_lo, got_hi = np.empty(n), np.empty(n)
        lat, trk = track_rows(arrays, cfg.track_margin, xbar, alat, AV21.lat_acc_max - 3.0, 0.5, got_lo, got_hi)
        assert (lat, trk) == (want_lat, want_trk)
        assert got_lo.tobytes() == want_lo.tobytes() and got_hi.tobytes() == want_hi.tobytes()


@pytest.mark.parametrize("shape", [(5,), (5, 21), (4, 3), (0, 3), (2, 3, 4)])
def test_all_finite_is_numpys(shape):
    from sofar_env.control.mpc.assembly import all_finite

    rng = np.random.default_rng(0)
    a = rng.normal(size=shape)
    assert all_finite(a) and all_finite(a.T)
    for bad in (np.nan, np.inf, -np.inf):
        if a.size:
            b = a.copy()
            b.flat[rng.integers(0, a.size)] = bad
            assert all_finite(b) == bool(np.isfinite(b).all()) is False
