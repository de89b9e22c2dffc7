"""DAQP's C API called from compiled kernels: ``daqp_quadprog`` without the Python wrapper.

The ``daqp`` wheel's extension module exports DAQP's C functions. Loaded into the process with
``llvmlite.binding.load_library_permanently`` and declared as a numba ``ExternalFunction``, its
``daqp_quadprog`` can be called from a kernel (:func:`sofar_env._jit.kernel`, cached on disk like the others),
so a kernel can build a QP, solve it and use the solution in one compiled call.

Contract of :func:`quadprog`: the same problem, settings and call as ``daqp.solve(H, f, A, bupper, blower,
sense, presolve=..., fval_bound=...)`` of the pinned version, so the same solution to the bit (DAQP is
deterministic; tests/planning/test_daqp_c.py compares the two on the closed-loop problems of the planner).
The C structs (``DAQPProblem``, ``DAQPSettings``, ``DAQPResult``) are laid out here as numpy record dtypes
copied from the headers of ``daqp`` :data:`DAQP_VERSION`; their layout changes between versions, so
:data:`AVAILABLE` is True only when the installed version is that one and DAQP's own
``daqp_default_settings`` fills the settings record with the defaults of ``daqp.solve`` (a check of the
layout). Otherwise a warning is logged once and the callers keep their ``daqp.solve`` route (same results).
Measurements and what stays numpy: docs/decisions/compiled-planner.md.
"""

from __future__ import annotations

import ctypes
import inspect
import logging
from importlib import metadata

import numpy as np
from numba import types

from .._jit import kernel

__all__ = ["DAQP_VERSION", "AVAILABLE", "PROBLEM", "SETTINGS", "RESULT", "Workspace", "quadprog"]

logger = logging.getLogger(__name__)

DAQP_VERSION = "0.11.0"
"""The ``daqp`` release whose C structs :data:`PROBLEM`, :data:`SETTINGS` and :data:`RESULT` copy."""

_i4, _f8, _ptr = np.int32, np.float64, np.uintp
PROBLEM = np.dtype([("n", _i4), ("m", _i4), ("ms", _i4), ("H", _ptr), ("f", _ptr), ("A", _ptr), ("bupper", _ptr),
                    ("blower", _ptr), ("sense", _ptr), ("break_points", _ptr), ("nh", _i4), ("problem_type", _i4)],
                   align=True)
"""``DAQPProblem`` (include/types.h): dimensions, pointers to the data, hierarchy and problem type."""
SETTINGS = np.dtype([("primal_tol", _f8), ("dual_tol", _f8), ("zero_tol", _f8), ("pivot_tol", _f8),
                     ("progress_tol", _f8), ("cycle_tol", _i4), ("iter_limit", _i4), ("fval_bound", _f8),
                     ("eps_prox", _f8), ("eta_prox", _f8), ("rho_soft", _f8), ("rel_subopt", _f8),
                     ("abs_subopt", _f8), ("sing_tol", _f8), ("refactor_tol", _f8), ("time_limit", _f8),
                     ("w_soft", _f8), ("eq_reduction", _i4), ("presolve", _i4)], align=True)
"""``DAQPSettings`` (include/types.h)."""
RESULT = np.dtype([("x", _ptr), ("lam", _ptr), ("fval", _f8), ("soft_slack", _f8), ("exitflag", _i4),
                   ("iter", _i4), ("nodes", _i4), ("solve_time", _f8), ("setup_time", _f8)], align=True)
"""``DAQPResult`` (include/api.h)."""

_quadprog = types.ExternalFunction("daqp_quadprog", types.void(types.uintp, types.uintp, types.uintp))
"""``void daqp_quadprog(DAQPResult*, DAQPProblem*, DAQPSettings*)`` (include/api.h)."""


def _solve_defaults() -> np.ndarray:
    """(1,) :data:`SETTINGS` record holding the keyword defaults of ``daqp.solve`` (what it passes to C)."""
    import daqp

    params = inspect.signature(daqp.solve).parameters
    out = np.zeros(1, SETTINGS)
    for name in SETTINGS.names:
        out[0][name] = params[name].default
    return out


def _load() -> bool:
    """Load DAQP's library for the kernels and check its version and the settings layout (module docstring)."""
    try:
        import daqp

        version = metadata.version("daqp")
    except Exception as exc:  # pragma: no cover - daqp is a hard dependency
        logger.warning("DAQP's C API not available (%r): the planner calls daqp.solve", exc)
        return False
    if version != DAQP_VERSION:
        logger.warning("daqp %s installed, the compiled DAQP calls are laid out for %s: the planner calls "
                       "daqp.solve instead (same results, slower)", version, DAQP_VERSION)
        return False
    try:
        import llvmlite.binding as llvm

        llvm.load_library_permanently(daqp.__file__)
        lib = ctypes.CDLL(daqp.__file__)
        guard = 8
        buf = np.full(SETTINGS.itemsize + guard, 0xA5, dtype=np.uint8)
        lib.daqp_default_settings(ctypes.c_void_p(buf.ctypes.data))
        filled = buf[:SETTINGS.itemsize].view(SETTINGS)
        expected = _solve_defaults()
        same = all(filled[0][k] == expected[0][k] for k in SETTINGS.names) and bool((buf[-guard:] == 0xA5).all())
    except Exception as exc:  # pragma: no cover - a broken install
        logger.warning("DAQP's C API could not be loaded (%r): the planner calls daqp.solve", exc)
        return False
    if not same:  # pragma: no cover - a rebuilt wheel with another layout
        logger.warning("DAQP's settings struct differs from the layout of daqp %s: the planner calls daqp.solve",
                       DAQP_VERSION)
    return same


AVAILABLE: bool = _load()
"""Whether :func:`quadprog` may be called (the pinned DAQP, its layout checked)."""


class Workspace:
    """The records and buffers of :func:`quadprog` calls of up to ``n`` variables and ``m`` constraints, reused
    from call to call: ``records`` = (problem, settings, result), ``buffers`` = (x, lam, sense)."""

    def __init__(self, n: int = 0, m: int = 0):
        settings = _solve_defaults() if AVAILABLE else np.zeros(1, SETTINGS)
        self.records = (np.zeros(1, PROBLEM), settings, np.zeros(1, RESULT))
        self.buffers = (np.empty(0), np.empty(0), np.empty(0, dtype=np.int32))
        self.reserve(n, m)

    def reserve(self, n: int, m: int) -> tuple:
        """The buffers, grown to hold ``n`` variables and ``m`` constraints."""
        x, lam, sense = self.buffers
        if x.shape[0] < n or lam.shape[0] < m:
            n, m = max(n, x.shape[0]), max(m, lam.shape[0])
            self.buffers = (np.empty(n), np.empty(m), np.empty(m, dtype=np.int32))
        return self.buffers


@kernel
def quadprog(H, f, A, bupper, blower, sense, fval_bound, presolve, records, buffers):
    """``daqp.solve(H, f, A, bupper, blower, sense, fval_bound=fval_bound, presolve=presolve)`` of the pinned
    DAQP (the other settings as ``records`` hold them: its defaults, but where a caller set one, such as the
    planner's ``cycle_tol``) in a kernel: returns ``(exitflag, fval)``; the solution is in
    ``buffers[0][:n]``. ``sense`` is copied to ``buffers[2]`` first (DAQP writes its working set into it),
    so it is left as given. ``H`` (n, n), ``A`` (m - ms, n) C-contiguous; ``bupper``, ``blower`` (m,) with the
    ``ms`` simple bounds first. Only with :data:`AVAILABLE` (module docstring)."""
    problem, settings, result = records
    x, lam, work_sense = buffers
    n = f.shape[0]
    m = bupper.shape[0]
    for i in range(m):
        work_sense[i] = sense[i]
    p = problem[0]
    p.n = n
    p.m = m
    p.ms = m - A.shape[0]
    p.H = H.ctypes.data
    p.f = f.ctypes.data
    p.A = A.ctypes.data if A.shape[0] > 0 else 0
    p.bupper = bupper.ctypes.data if m > 0 else 0
    p.blower = blower.ctypes.data if m > 0 else 0
    p.sense = work_sense.ctypes.data if m > 0 else 0
    p.break_points = 0
    p.nh = 0
    p.problem_type = 0
    s = settings[0]
    s.fval_bound = fval_bound
    s.presolve = presolve
    r = result[0]
    r.x = x.ctypes.data
    r.lam = lam.ctypes.data if m > 0 else 0
    r.fval = 0.0
    r.soft_slack = 0.0
    r.exitflag = 0
    r.iter = 0
    r.nodes = 0
    r.solve_time = 0.0
    r.setup_time = 0.0
    _quadprog(result.ctypes.data, problem.ctypes.data, settings.ctypes.data)
    # the arrays the pointers refer to are arguments: alive until the kernel returns
    return result[0].exitflag, result[0].fval
