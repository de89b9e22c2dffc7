"""DAQP's C API called from compiled kernels: ``daqp_quadprog`` and a soft-weighted solve without the Python wrapper.

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

Contract of :func:`soft_solve`: the problem of ``daqp.Model.setup`` (or ``update`` with every matrix and a fresh
``sense``), then ``Model.soft_weights(rho, rho, w, w)`` and ``Model.solve()``, settings as ``records`` hold them,
through DAQP's documented C calls (``setup_daqp``, ``daqp_set_soft_weights``, ``daqp_solve``, then
``free_daqp_workspace`` and ``free_daqp_ldp``): the same solution to the bit
(tests/control/mpc/test_condensed_c.py).
The workspace ``DAQPWorkspace`` is opaque here: a zeroed buffer of :data:`WORKSPACE_BYTES`, of which only the
slot of its ``settings`` pointer is known, found at import (:data:`SETTINGS_SLOT`: the one pointer
``allocate_daqp_settings`` writes into a zeroed buffer). Our settings record is put there before the setup and
taken out before the workspace is freed, as ``daqp_quadprog`` does with the settings it is given. At import a
small soft QP is set up, solved and freed through these calls and checked against ``daqp.Model`` and against
the buffer's tail, which DAQP must leave untouched (:data:`SOFT_AVAILABLE`).
"""

from __future__ import annotations

import ctypes
import inspect
import logging
from importlib import metadata

import numpy as np
from numba import types

from .._jit import kernel

__all__ = ["DAQP_VERSION", "AVAILABLE", "SOFT_AVAILABLE", "PROBLEM", "SETTINGS", "RESULT", "WORKSPACE_BYTES",
           "SETTINGS_SLOT", "Workspace", "quadprog", "soft_solve"]

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
_u = types.uintp
_setup = types.ExternalFunction("setup_daqp", types.int32(_u, _u, _u))
"""``int setup_daqp(DAQPProblem*, DAQPWorkspace*, c_float* setup_time)``."""
_set_soft_weights = types.ExternalFunction("daqp_set_soft_weights", types.int32(_u, _u, _u, _u, _u))
"""``int daqp_set_soft_weights(DAQPWorkspace*, c_float* rho_l, c_float* rho_u, c_float* w_l, c_float* w_u)``: 0
when the build has no per-row weights."""
_solve = types.ExternalFunction("daqp_solve", types.void(_u, _u))
"""``void daqp_solve(DAQPResult*, DAQPWorkspace*)``."""
_free_workspace = types.ExternalFunction("free_daqp_workspace", types.void(_u))
_free_ldp = types.ExternalFunction("free_daqp_ldp", types.void(_u))

WORKSPACE_BYTES = 1024
"""Bytes of the opaque ``DAQPWorkspace`` buffer of :func:`soft_solve`; DAQP uses the first
:data:`_WORKSPACE_USED` (checked at import: the rest stays as written)."""
_WORKSPACE_USED = 512


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


def _settings_slot() -> int:
    """The 8-byte slot of ``DAQPWorkspace.settings``: the one slot ``allocate_daqp_settings`` fills in a zeroed
    buffer (-1 if that is not exactly one)."""
    import daqp

    lib = ctypes.CDLL(daqp.__file__)
    buf = np.zeros(WORKSPACE_BYTES // 8, dtype=np.uint64)
    lib.allocate_daqp_settings(ctypes.c_void_p(buf.ctypes.data))
    filled = np.flatnonzero(buf)
    lib.free_daqp_workspace(ctypes.c_void_p(buf.ctypes.data))  # frees the settings, nothing else is allocated
    if len(filled) != 1 or filled[0] * 8 >= _WORKSPACE_USED or buf.any():
        return -1
    return int(filled[0])


SETTINGS_SLOT: int = _settings_slot() if AVAILABLE else -1
"""Index (in 8-byte words) of the ``settings`` pointer in the workspace buffer; -1 when not found."""


def _soft_check() -> bool:
    """The calls of :func:`soft_solve`, made through ctypes on a small QP with two soft rows of their own weights
    (one of them violated at the optimum), give ``daqp.Model``'s solution to the bit and leave the buffer's tail
    and the settings record as they were."""
    import daqp

    lib = ctypes.CDLL(daqp.__file__)
    H = np.array([[2.0, 0.5], [0.5, 1.0]])
    f = np.array([-1.0, 0.3])
    A = np.array([[1.0, 1.0], [1.0, -2.0]])
    bu = np.array([1.0, 1.0, -0.5, 0.2])
    bl = np.array([-1.0, -1.0, -np.inf, -0.2])
    sense = np.array([0, 0, 8, 8], dtype=np.int32)
    rho = np.array([0.0, 0.0, 0.3, 2.0])
    w = np.array([0.0, 0.0, 0.1, 0.0])
    model = daqp.Model()
    model.setup(H, f, A, bu, bl, sense.copy())
    model.soft_weights(rho_l=rho, rho_u=rho, w_l=w, w_u=w)
    x_ref, _, flag_ref, _ = model.solve()
    ws = Workspace()
    problem, settings, result = ws.records
    before = settings.tobytes()
    work = np.zeros(WORKSPACE_BYTES // 8, dtype=np.uint64)
    work[_WORKSPACE_USED // 8:] = 0xA5A5A5A5A5A5A5A5
    x, lam, s = np.zeros(2), np.zeros(4), sense.copy()
    problem[0] = (2, 4, 2, H.ctypes.data, f.ctypes.data, A.ctypes.data, bu.ctypes.data, bl.ctypes.data,
                  s.ctypes.data, 0, 0, 0)
    result["x"], result["lam"] = x.ctypes.data, lam.ctypes.data
    work[SETTINGS_SLOT] = settings.ctypes.data
    vp = ctypes.c_void_p
    lib.setup_daqp.restype = lib.daqp_set_soft_weights.restype = ctypes.c_int
    if lib.setup_daqp(vp(problem.ctypes.data), vp(work.ctypes.data), None) < 0:
        return False
    ok = lib.daqp_set_soft_weights(vp(work.ctypes.data), *(vp(a.ctypes.data) for a in (rho, rho, w, w)))
    if ok:
        lib.daqp_solve(vp(result.ctypes.data), vp(work.ctypes.data))
    work[SETTINGS_SLOT] = 0
    lib.free_daqp_workspace(vp(work.ctypes.data))
    lib.free_daqp_ldp(vp(work.ctypes.data))
    return bool(ok and flag_ref == 2 and result[0]["exitflag"] == flag_ref and np.array_equal(x, x_ref)
                and (work[_WORKSPACE_USED // 8:] == 0xA5A5A5A5A5A5A5A5).all() and settings.tobytes() == before)


def _soft_available() -> bool:
    """:func:`_soft_check`, with a warning when it fails."""
    if not AVAILABLE or SETTINGS_SLOT < 0:
        return False
    try:
        ok = _soft_check()
    except Exception as exc:  # pragma: no cover - a broken install
        logger.warning("DAQP's soft-weighted C calls could not be checked (%r): the MPC calls daqp.Model", exc)
        return False
    if not ok:  # pragma: no cover - a rebuilt wheel with another layout
        logger.warning("DAQP's soft-weighted C calls differ from daqp.Model's: the MPC calls daqp.Model")
    return ok


class Workspace:
    """The records and buffers of :func:`quadprog` calls of up to ``n`` variables and ``m`` constraints, reused
    from call to call: ``records`` = (problem, settings, result), ``buffers`` = (x, lam, sense)."""

    def __init__(self, n: int = 0, m: int = 0):
        settings = _solve_defaults() if AVAILABLE else np.zeros(1, SETTINGS)
        self.records = (np.zeros(1, PROBLEM), settings, np.zeros(1, RESULT))
        self.buffers = (np.empty(0), np.empty(0), np.empty(0, dtype=np.int32))
        self.work = np.zeros(WORKSPACE_BYTES // 8, dtype=np.uint64)
        """The opaque ``DAQPWorkspace`` of :func:`soft_solve` (zero between calls)."""
        self.reserve(n, m)

    def reserve(self, n: int, m: int) -> tuple:
        """The buffers, grown to hold ``n`` variables and ``m`` constraints."""
        x, lam, sense = self.buffers
        if x.shape[0] < n or lam.shape[0] < m:
            n, m = max(n, x.shape[0]), max(m, lam.shape[0])
            self.buffers = (np.empty(n), np.empty(m), np.empty(m, dtype=np.int32))
        return self.buffers


@kernel
def _fill_records(H, f, A, bupper, blower, sense, records, buffers):
    """The problem record pointing at the data and the result record at the buffers (their settings record is
    left alone); ``sense`` copied to ``buffers[2]`` (DAQP writes its working set there). The pointers are valid
    while the arrays live: the caller's arguments, until it returns."""
    problem, _, result = records
    x, lam, work_sense = buffers
    m = bupper.shape[0]
    for i in range(m):
        work_sense[i] = sense[i]
    p = problem[0]
    p.n = f.shape[0]
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


@kernel
def quadprog(H, f, A, bupper, blower, sense, fval_bound, presolve, records, buffers):
    """``daqp.solve(H, f, A, bupper, blower, sense, fval_bound=fval_bound, presolve=presolve)`` of the pinned
    DAQP (the other settings as ``records`` hold them: its defaults, but where a caller set one, such as the
    planner's ``cycle_tol``) in a kernel: returns ``(exitflag, fval)``; the solution is in
    ``buffers[0][:n]``. ``sense`` is copied to ``buffers[2]`` first (DAQP writes its working set into it),
    so it is left as given. ``H`` (n, n), ``A`` (m - ms, n) C-contiguous; ``bupper``, ``blower`` (m,) with the
    ``ms`` simple bounds first. Only with :data:`AVAILABLE` (module docstring)."""
    problem, settings, result = records
    _fill_records(H, f, A, bupper, blower, sense, records, buffers)
    s = settings[0]
    s.fval_bound = fval_bound
    s.presolve = presolve
    _quadprog(result.ctypes.data, problem.ctypes.data, settings.ctypes.data)
    # the arrays the pointers refer to are arguments: alive until the kernel returns
    return result[0].exitflag, result[0].fval


@kernel
def soft_solve(H, f, A, bupper, blower, sense, rho, w, records, buffers, work, slot):
    """``Model.setup(H, f, A, bupper, blower, sense)``, ``Model.soft_weights(rho, rho, w, w)`` and ``Model.solve()``
    of the pinned DAQP in a kernel (module docstring), with the settings of ``records``: returns ``(setup_flag,
    exitflag, iterations)``: ``setup_flag`` < 0 where the setup failed, 0 where the build has no per-row weights
    (nothing solved then), 1 where it solved; the solution is in ``buffers[0][:n]``.
    ``sense`` is copied first (left as given); ``rho``, ``w`` one entry per constraint, simple bounds first (a zero
    entry: DAQP's uniform ``rho_soft`` / ``w_soft``). ``work`` a zeroed :data:`WORKSPACE_BYTES` buffer (zeroed again
    on return), ``slot`` :data:`SETTINGS_SLOT` (an argument, not a global: a kernel's cache would freeze a global).
    Only with :data:`SOFT_AVAILABLE`."""
    problem, settings, result = records
    _fill_records(H, f, A, bupper, blower, sense, records, buffers)
    work[slot] = settings.ctypes.data  # DAQP uses, and does not free, settings it is given
    setup_flag = _setup(problem.ctypes.data, work.ctypes.data, 0)
    if setup_flag < 0:  # DAQP has freed what it allocated and dropped the settings pointer
        for i in range(work.shape[0]):
            work[i] = 0
        return setup_flag, 0, 0
    setup_flag = 1
    if _set_soft_weights(work.ctypes.data, rho.ctypes.data, rho.ctypes.data, w.ctypes.data, w.ctypes.data) == 0:
        setup_flag = 0
    else:
        _solve(result.ctypes.data, work.ctypes.data)
    work[slot] = 0
    _free_workspace(work.ctypes.data)
    _free_ldp(work.ctypes.data)
    for i in range(work.shape[0]):
        work[i] = 0
    return setup_flag, result[0].exitflag, result[0].iter


SOFT_AVAILABLE: bool = _soft_available()
"""Whether :func:`soft_solve` may be called (:data:`AVAILABLE`, the settings slot found, the import check passed)."""
