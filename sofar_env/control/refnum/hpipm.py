"""HPIPM's dense QP interior-point solver, called through its C API.

HPIPM is the QP solver of acados' ``FULL_CONDENSING_HPIPM``, the solver of the reference
implementation of the paper. CasADi's wheels ship HPIPM and BLASFEO as shared libraries (for
CasADi's own ``hpipm`` QP plugin); this module loads that library with :mod:`ctypes` and calls
HPIPM's dense QP functions directly, so that the same interior-point iterations run here, with the
same options, on the same condensed QP, with no install step beyond CasADi.

Only HPIPM's public API is used: every structure is allocated from the sizes HPIPM reports
(``*_strsize``, ``*_memsize``), so no structure layout is assumed.

:class:`DenseQP` holds one problem size (nv variables, nb box bounds on variables, ng general
constraints, ns softened constraints) and solves ``min 1/2 v'Hv + g'v`` subject to
``lb <= v[idxb] <= ub``, ``lg <= Cv <= ug`` with the constraints listed in ``idxs`` softened by
slacks ``sl, su >= 0`` that cost ``1/2 Z s^2 + z s``. :func:`acados_options` returns the options
acados (v0.4.3) gives HPIPM's dense solver: the ``BALANCE`` mode with 50 iterations at most,
``mu0 = 1``, ``alpha_min = 1e-8`` and tolerances 1e-6 (stationarity) and 1e-8 (the others).
"""

from __future__ import annotations

import ctypes
import os

import numpy as np

from ...configs.refnum import MODES, HPIPMOptions

__all__ = ["HPIPMUnavailable", "HPIPMOptions", "acados_options", "DenseQP", "STATUS_NAMES", "library_path"]

STATUS_NAMES = {0: "success", 1: "max_iter", 2: "min_step", 3: "nan", 4: "inconsistent_eq"}
"""HPIPM's ``enum hpipm_status``."""


class HPIPMUnavailable(RuntimeError):
    """CasADi's build of HPIPM could not be found or loaded."""




def acados_options() -> HPIPMOptions:
    """The options acados v0.4.3 sets for HPIPM's dense solver (``dense_qp_hpipm.c``)."""
    return HPIPMOptions()


def library_path() -> str:
    """Path of the HPIPM shared library that ships with CasADi."""
    import casadi

    path = os.path.join(os.path.dirname(casadi.__file__), "libhpipm.so")
    if not os.path.exists(path):
        raise HPIPMUnavailable(f"CasADi {casadi.__version__} has no HPIPM library at {path}")
    return path


def _load() -> ctypes.CDLL:
    try:
        lib = ctypes.CDLL(library_path())
    except OSError as exc:
        raise HPIPMUnavailable(f"cannot load HPIPM: {exc}") from exc
    size_t, vp, dp, ip = ctypes.c_uint64, ctypes.c_void_p, ctypes.POINTER(ctypes.c_double), ctypes.POINTER(ctypes.c_int)
    for name in ("d_dense_qp_dim_strsize", "d_dense_qp_dim_memsize", "d_dense_qp_strsize",
                 "d_dense_qp_sol_strsize", "d_dense_qp_ipm_arg_strsize", "d_dense_qp_ipm_ws_strsize"):
        getattr(lib, name).restype = size_t
        getattr(lib, name).argtypes = []
    for name in ("d_dense_qp_memsize", "d_dense_qp_sol_memsize", "d_dense_qp_ipm_arg_memsize"):
        getattr(lib, name).restype = size_t
        getattr(lib, name).argtypes = [vp]
    lib.d_dense_qp_ipm_ws_memsize.restype = size_t
    lib.d_dense_qp_ipm_ws_memsize.argtypes = [vp, vp]
    lib.d_dense_qp_dim_create.argtypes = [vp, vp]
    lib.d_dense_qp_dim_set_all.argtypes = [ctypes.c_int] * 5 + [vp]
    for name in ("d_dense_qp_create", "d_dense_qp_sol_create", "d_dense_qp_ipm_arg_create"):
        getattr(lib, name).argtypes = [vp, vp, vp]
    lib.d_dense_qp_ipm_ws_create.argtypes = [vp, vp, vp, vp]
    lib.d_dense_qp_ipm_arg_set_default.argtypes = [ctypes.c_int, vp]
    lib.d_dense_qp_ipm_arg_set_iter_max.argtypes = [ip, vp]
    for name in ("mu0", "alpha_min", "tol_stat", "tol_eq", "tol_ineq", "tol_comp"):
        getattr(lib, f"d_dense_qp_ipm_arg_set_{name}").argtypes = [dp, vp]
    for name in ("H", "g", "C", "lg", "ug", "lb", "ub", "Zl", "Zu", "zl", "zu", "lls", "lus"):
        getattr(lib, f"d_dense_qp_set_{name}").argtypes = [dp, vp]
    lib.d_dense_qp_set_idxb.argtypes = [ip, vp]
    lib.d_dense_qp_set_idxs.argtypes = [ip, vp]
    lib.d_dense_qp_ipm_solve.argtypes = [vp, vp, vp, vp]
    lib.d_dense_qp_ipm_get_status.argtypes = [vp, ip]
    lib.d_dense_qp_ipm_get_iter.argtypes = [vp, ip]
    lib.d_dense_qp_sol_get_v.argtypes = [vp, dp]
    return lib


_LIB: list = []  # the loaded library (loaded once per process; ctypes handles are immutable)


def _lib() -> ctypes.CDLL:
    if not _LIB:
        _LIB.append(_load())
    return _LIB[0]


def _dp(a: np.ndarray):
    return a.ctypes.data_as(ctypes.POINTER(ctypes.c_double))


def _ip(a: np.ndarray):
    return a.ctypes.data_as(ctypes.POINTER(ctypes.c_int))


class DenseQP:
    """One dense QP size, its HPIPM workspace and options (see the module docstring).

    ``idxb`` are the variables with box bounds, ``idxs`` the softened constraints, as indices into
    the stacked constraints ``[box bounds (nb), general constraints (ng)]``. Not thread-safe; build
    one per controller. The object cannot be pickled: rebuild it from its arguments.
    """

    def __init__(self, nv: int, idxb: np.ndarray, ng: int, idxs: np.ndarray,
                 options: HPIPMOptions = HPIPMOptions()):
        lib = _lib()
        self.nv, self.ng = int(nv), int(ng)
        self.idxb = np.ascontiguousarray(idxb, dtype=np.intc)
        self.idxs = np.ascontiguousarray(idxs, dtype=np.intc)
        self.nb, self.ns = len(self.idxb), len(self.idxs)
        self.options = options
        self._keep = []  # every buffer HPIPM points into lives as long as this object

        def buffer(size: int):
            buf = ctypes.create_string_buffer(int(size) + 64)
            self._keep.append(buf)
            return ctypes.cast(buf, ctypes.c_void_p)

        self._dim = buffer(lib.d_dense_qp_dim_strsize())
        lib.d_dense_qp_dim_create(self._dim, buffer(lib.d_dense_qp_dim_memsize()))
        lib.d_dense_qp_dim_set_all(self.nv, 0, self.nb, self.ng, self.ns, self._dim)
        self._qp = buffer(lib.d_dense_qp_strsize())
        lib.d_dense_qp_create(self._dim, self._qp, buffer(lib.d_dense_qp_memsize(self._dim)))
        self._sol = buffer(lib.d_dense_qp_sol_strsize())
        lib.d_dense_qp_sol_create(self._dim, self._sol, buffer(lib.d_dense_qp_sol_memsize(self._dim)))
        self._arg = buffer(lib.d_dense_qp_ipm_arg_strsize())
        lib.d_dense_qp_ipm_arg_create(self._dim, self._arg, buffer(lib.d_dense_qp_ipm_arg_memsize(self._dim)))
        lib.d_dense_qp_ipm_arg_set_default(MODES[options.mode], self._arg)
        lib.d_dense_qp_ipm_arg_set_iter_max(ctypes.byref(ctypes.c_int(options.iter_max)), self._arg)
        for name in ("mu0", "alpha_min", "tol_stat", "tol_eq", "tol_ineq", "tol_comp"):
            getattr(lib, f"d_dense_qp_ipm_arg_set_{name}")(ctypes.byref(ctypes.c_double(getattr(options, name))),
                                                           self._arg)
        self._ws = buffer(lib.d_dense_qp_ipm_ws_strsize())
        lib.d_dense_qp_ipm_ws_create(self._dim, self._arg, self._ws,
                                     buffer(lib.d_dense_qp_ipm_ws_memsize(self._dim, self._arg)))
        lib.d_dense_qp_set_idxb(_ip(self.idxb), self._qp)
        lib.d_dense_qp_set_idxs(_ip(self.idxs), self._qp)
        zeros = np.zeros(self.ns)
        lib.d_dense_qp_set_lls(_dp(zeros), self._qp)
        lib.d_dense_qp_set_lus(_dp(zeros), self._qp)
        self._v = np.zeros(self.nv)

    def solve(self, H, g, lb, ub, C, lg, ug, Z, z) -> tuple[np.ndarray, int, int]:
        """``(v, status, iterations)``: HPIPM's last iterate (a copy), its status (:data:`STATUS_NAMES`)
        and the number of iterations. ``Z``, ``z``: the slacks' quadratic and linear weights, the same on
        both sides. The iterate is returned whatever the status: a caller decides what a status means."""
        lib = _lib()
        qp = self._qp
        f64 = np.float64
        H = np.asfortranarray(H, dtype=f64)
        C = np.asfortranarray(C, dtype=f64)
        vecs = [np.ascontiguousarray(a, dtype=f64) for a in (g, lb, ub, lg, ug, Z, z)]
        g, lb, ub, lg, ug, Z, z = vecs
        lib.d_dense_qp_set_H(_dp(H), qp)
        lib.d_dense_qp_set_g(_dp(g), qp)
        lib.d_dense_qp_set_lb(_dp(lb), qp)
        lib.d_dense_qp_set_ub(_dp(ub), qp)
        lib.d_dense_qp_set_C(_dp(C), qp)
        lib.d_dense_qp_set_lg(_dp(lg), qp)
        lib.d_dense_qp_set_ug(_dp(ug), qp)
        lib.d_dense_qp_set_Zl(_dp(Z), qp)
        lib.d_dense_qp_set_Zu(_dp(Z), qp)
        lib.d_dense_qp_set_zl(_dp(z), qp)
        lib.d_dense_qp_set_zu(_dp(z), qp)
        lib.d_dense_qp_ipm_solve(qp, self._sol, self._arg, self._ws)
        status, iters = ctypes.c_int(0), ctypes.c_int(0)
        lib.d_dense_qp_ipm_get_status(self._ws, ctypes.byref(status))
        lib.d_dense_qp_ipm_get_iter(self._ws, ctypes.byref(iters))
        lib.d_dense_qp_sol_get_v(self._sol, _dp(self._v))
        return self._v.copy(), int(status.value), int(iters.value)
