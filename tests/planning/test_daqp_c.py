"""Tests of DAQP's C API called from kernels (sofar_env.planning.daqp_c) and of the branch and bound's compiled
route, against ``daqp.solve`` bit for bit."""

from __future__ import annotations

from importlib import metadata

import numpy as np
import pytest

from sofar_env.planning import daqp_c, solvers

from .test_solvers import _closed_loop_problems

pytestmark = pytest.mark.skipif(not daqp_c.AVAILABLE, reason="another daqp than the pinned one: no C route")


def test_the_pinned_version_is_installed_and_its_settings_layout_checked():
    """The C route is on exactly when the installed daqp is the pinned one (its layout checked at import)."""
    assert metadata.version("daqp") == daqp_c.DAQP_VERSION
    assert solvers.NATIVE
    assert (daqp_c.PROBLEM.itemsize, daqp_c.SETTINGS.itemsize, daqp_c.RESULT.itemsize) == (80, 136, 64)


def test_quadprog_is_daqp_solve_to_the_bit():
    """Random QPs with simple bounds, general rows, binaries, soft rows and a bound on the objective: the kernel
    returns daqp.solve's x, objective and exit flag, and leaves ``sense`` as given."""
    import daqp

    rng = np.random.default_rng(4)
    work = daqp_c.Workspace()
    flags = set()
    for trial in range(60):
        n, ms, ma = int(rng.integers(2, 9)), 0, int(rng.integers(0, 7))
        ms = int(rng.integers(0, n + 1))
        L = rng.standard_normal((n, n))
        H = L @ L.T + 0.5 * np.eye(n) if trial % 2 else np.diag(rng.uniform(0.5, 2.0, n))
        f = rng.standard_normal(n)
        A = rng.standard_normal((ma, n))
        bupper = np.concatenate([rng.uniform(0.2, 2.0, ms), rng.uniform(-0.5, 2.0, ma)])
        blower = np.concatenate([-rng.uniform(0.2, 2.0, ms), bupper[ms:] - rng.uniform(0.0, 3.0, ma)])
        sense = np.zeros(ms + ma, dtype=np.int32)
        if ms and trial % 3 == 0:
            sense[0] = 16
            bupper[0], blower[0] = 1.0, 0.0
        if ma and trial % 4 == 1:
            sense[ms] = 8
        bound = 1e30 if trial % 5 else -1.0
        presolve = trial % 2
        x_ref, fval_ref, flag_ref, _ = daqp.solve(H, f, A, bupper, blower, sense.copy(), fval_bound=bound,
                                                  presolve=presolve)
        given = sense.copy()
        records, buffers = work.records, work.reserve(n, ms + ma)
        flag, fval = daqp_c.quadprog(H, f, A, bupper, blower, sense, bound, presolve, records, buffers)
        assert flag == flag_ref
        flags.add(flag)
        np.testing.assert_array_equal(sense, given)
        if flag in (1, 2):
            assert fval == fval_ref
            np.testing.assert_array_equal(buffers[0][:n], x_ref)
    assert 1 in flags and -1 in flags


def test_the_compiled_branch_and_bound_route_is_the_python_route():
    """Closed-loop-like problems (sides locked by cars alongside among them): the compiled route (data,
    incumbent, DAQP through its C API) returns the plan and the sides of the Python route, bit for bit."""
    seen = _closed_loop_problems(seed=13, alongside_gap=8.0) + _closed_loop_problems(seed=2)
    assert len(seen) > 30
    cache: dict = {}
    for prob, w_slack, out in seen:
        assert out is not None
        solvers.NATIVE = False
        try:
            python = solvers.solve_branch_and_bound(prob, w_slack, {})
        finally:
            solvers.NATIVE = True
        native = solvers.solve_branch_and_bound(prob, w_slack, cache)
        for a, b, c in zip(python, native, out):
            np.testing.assert_array_equal(a, b)
            np.testing.assert_array_equal(b, c)


def test_another_daqp_version_keeps_the_python_route_with_a_warning(monkeypatch, caplog):
    """A daqp other than the pinned one: the C route is refused (its structs may be laid out otherwise), one
    warning says so."""
    import logging

    monkeypatch.setattr(daqp_c.metadata, "version", lambda name: "0.0.1")
    with caplog.at_level(logging.WARNING, logger="sofar_env.planning.daqp_c"):
        assert daqp_c._load() is False
    assert any("0.0.1" in r.getMessage() and daqp_c.DAQP_VERSION in r.getMessage() for r in caplog.records)
