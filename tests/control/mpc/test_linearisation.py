"""Compiled evaluation of the stage linearisation: cache on disk, same numbers as CasADi's own."""

import numpy as np
import pytest

from sofar_env.control.mpc import MPCConfig, MPCDCBF
from sofar_env.control.mpc.linearisation import StageLinearisation
from sofar_env.vehicle import AV21

from .scenarios import make_stage


def test_compiled_library_is_cached(tmp_path):
    first = MPCDCBF(MPCConfig(cache_dir=str(tmp_path)))
    if not first.codegen_info.compiled:
        pytest.skip(f"no working C compiler: {first.codegen_info.message}")
    assert first.codegen_info.built_now
    second = MPCDCBF(MPCConfig(cache_dir=str(tmp_path)))
    assert second.codegen_info.compiled and not second.codegen_info.built_now
    assert second.codegen_info.path == first.codegen_info.path
    assert len(list(tmp_path.glob("*.so"))) == 1
    # a different problem definition gets its own library
    third = MPCDCBF(MPCConfig(cache_dir=str(tmp_path), max_opponents=3))
    assert third.codegen_info.built_now and third.codegen_info.path != first.codegen_info.path
    # compiled and CasADi evaluation give the same control
    x0 = np.array([0.0, 0.4, 0.01, 38.0, 0.01])
    opp = np.array([[25.0, 0.5, 30.0]])
    plain = MPCDCBF(MPCConfig(cache_dir=str(tmp_path), compile=False))
    assert not plain.codegen_info.compiled
    a = second.solve(x0, make_stage(), opp, 0.3)
    b = plain.solve(x0, make_stage(), opp, 0.3)
    np.testing.assert_allclose(a.u, b.u, atol=1e-6)


def test_evaluation_fills_the_arrays_with_the_stage_function(cache_dir):
    cfg = MPCConfig(cache_dir=cache_dir, max_opponents=2)
    t = cfg.time_grid()
    lin = StageLinearisation(cfg, AV21, np.diff(t))
    rng = np.random.default_rng(4)
    xbar = np.column_stack([38.0 * t, rng.uniform(-1, 1, len(t)), rng.uniform(-0.02, 0.02, len(t)),
                            38.0 + rng.uniform(-1, 1, len(t)), rng.uniform(-0.05, 0.05, len(t))])
    ubar = np.column_stack([rng.uniform(-3, 2, cfg.horizon), rng.uniform(-0.2, 0.2, cfg.horizon)])
    kappa = rng.uniform(-0.01, 0.01, len(t))
    rows = np.array([[30.0, 1.0, 35.0]])
    lin.set_opponents(rows, t)
    lin.evaluate(xbar, ubar, kappa)
    u_ext = np.vstack([ubar, [0.0, 0.0]])
    dt = np.concatenate([np.diff(t), [cfg.ts]])
    for k in (0, 7, cfg.horizon):
        f, alat, h = (np.asarray(v).ravel() for v in lin.stage(xbar[k], u_ext[k], kappa[k], dt[k], lin.o[k].T))
        np.testing.assert_allclose(lin.f[k], f, rtol=1e-14, atol=1e-12)
        assert lin.alat[k] == pytest.approx(alat[0], rel=1e-14, abs=1e-14)
        np.testing.assert_allclose(lin.h[k], h, rtol=1e-14)
    np.testing.assert_allclose(lin.o[:, 0, 0], 30.0 + 35.0 * t)
    assert np.all(lin.o[:, 1] == (50.0, 0.0, 0.0, 0.0))  # the unused slot holds the dummy
    lin.set_opponents(rows[:0], t)
    assert np.all(lin.o[:, 0] == (50.0, 0.0, 0.0, 0.0))


def test_the_compiled_barrier_sees_the_opponents_course(cache_dir):
    """With BarrierParams.heading_extent, opponent rows with a lateral rate (s, n, v, n_dot) reach the
    compiled barrier with the sine of their course angle n_dot / v: its h is the numeric barrier of the
    predicted rows (s, n, v, sin_course) and lies below that of an opponent without a rate."""
    from sofar_env.control.barrier import BarrierParams, barrier

    cfg = MPCConfig(cache_dir=cache_dir, max_opponents=2, barrier=BarrierParams(heading_extent=2.45))
    t = cfg.time_grid()
    lin = StageLinearisation(cfg, AV21, np.diff(t))
    xbar = np.column_stack([30.0 * t, np.zeros_like(t), np.full_like(t, 0.1), np.full_like(t, 30.0), np.zeros_like(t)])
    ubar = np.zeros((cfg.horizon, 2))
    rows = np.array([[12.0, 3.0, 28.0, -5.6], [12.0, 3.0, 28.0, 0.0]])
    lin.set_opponents(rows, t)
    np.testing.assert_allclose(lin.o[:, 0, 3], -0.2)
    lin.evaluate(xbar, ubar, np.zeros_like(t))
    for k in (0, 5):
        np.testing.assert_allclose(lin.h[k], barrier(xbar[k][None, :], lin.o[k], cfg.barrier), rtol=1e-12)
    assert lin.h[0, 0] < lin.h[0, 1]


def test_evaluate_copies_its_inputs(cache_dir):
    cfg = MPCConfig(cache_dir=cache_dir)
    lin = StageLinearisation(cfg, AV21, np.diff(cfg.time_grid()))
    rng = np.random.default_rng(4)
    xbar, ubar, kappa = rng.normal(size=(cfg.horizon + 1, 5)), rng.normal(size=(cfg.horizon, 2)), rng.normal(size=cfg.horizon + 1)
    lin.u[-1] = 5.0
    lin.evaluate(xbar, ubar, kappa)
    assert lin.x.tobytes() == xbar.tobytes() and lin.kappa.tobytes() == kappa.tobytes()
    assert lin.u[:-1].tobytes() == ubar.tobytes() and np.all(lin.u[-1] == 0.0)
