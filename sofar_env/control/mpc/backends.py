"""QP backends of the real-time iteration: PIQP (default), DAQP (condensed, dense) and OSQP (comparison only).

* ``"piqp"``: proximal interior point, eps_abs 1e-7; on the 600-step closed loop of
  ``bench/bench_mpc.py`` its first control differs from a 1e-11-tolerance solve from the
  same warm start by 1e-5 m/s^2 (p95), at most 1.2e-3 m/s^2; with ``qp_eps_rel = 1e-9``
  by 4e-7 (p95), at most 3.4e-5 m/s^2, for about 0.5 more interior-point iterations per
  solve (5-6 median);
* ``"osqp"``: ADMM (eps 1e-4, warm-started, at most 4000 iterations). With the slack
  scaling its first control errs by 4e-4 m/s^2 (p95) but up to 0.07 m/s^2, its solve
  time is heavy-tailed (p95 about 10x the median), and with an active barrier from a
  cold start it can hit the iteration limit (-> fallback). For comparison only;
* ``"daqp"``: the same QP condensed onto its 2 N input steps, slacks as DAQP's soft rows with
  their own weights (explicit variables where one slack serves rows with different coefficients),
  solved by DAQP's dual active-set method (:mod:`.condensed`). Its model is warm-started with the
  previous active set of the same pattern; it is not carried by a copied structure.

Each :class:`~.layout.QPStructure` keeps its own solver instance, set up once and
refreshed with ``update()`` (the pattern is fixed; a left-out bound is an infinite entry
of the bound vectors, not a change of pattern). :func:`solve_qp` never raises for
numerical trouble: it returns ``None`` and a message, and drops the instance so that
the next call sets the solver up afresh. A copied structure (no solver, but the data of the
original's set-up in ``QPStructure.solver_setup`` and its number of updates in ``solver_updates``)
gets a PIQP instance set up on those data, updated as often without data and then to the current
data: the state of the original's, to the bit (:class:`~.layout.QPStructure`).

With ``MPCConfig.qp_fallback = "daqp"`` a QP the backend fails on is solved once more by the condensed DAQP
backend (its model kept in ``QPStructure.fallback``, set up on the first such QP, not carried by a copy); the
message :data:`FALLBACK_SOLVED` tells the caller, which counts it. PIQP can fail on a feasible QP far outside its
soft track rows (``docs/decisions/qp-backend.md``).
"""

from __future__ import annotations

import numpy as np
import piqp
import scipy.sparse as sp

from ..._jit import kernel
from .assembly import all_finite
from .layout import QPStructure
from .types import MPCConfig

__all__ = ["solve_qp", "dcbf_margin", "FALLBACK_SOLVED"]

FALLBACK_SOLVED = "solved by the fallback backend"
"""The message of a QP that the first backend failed on and ``MPCConfig.qp_fallback`` solved."""


def solve_qp(qs: QPStructure, data: tuple, cfg: MPCConfig) -> tuple[np.ndarray | None, int, str]:
    """Solve the QP in ``qs`` (matrices) and ``data`` (c, b, h_l, h_u, x_l, x_u).

    Returns ``(z or None, iterations, message)``. Where the backend fails and ``cfg.qp_fallback`` names another
    one, that one solves the same QP (message :data:`FALLBACK_SOLVED` when it succeeds; the iterations are
    both backends').
    """
    z, iters, message = _solve_once(qs, data, cfg)
    if z is None and cfg.qp_fallback != "off" and cfg.qp_fallback != qs.backend:
        z, more, second = _solve_fallback(qs, data)
        return z, iters + more, (FALLBACK_SOLVED if z is not None else f"{message}; the fallback: {second}")
    return z, iters, message


def _solve_once(qs: QPStructure, data: tuple, cfg: MPCConfig) -> tuple[np.ndarray | None, int, str]:
    """The QP by the structure's own backend (:func:`solve_qp` without the fallback)."""
    try:
        if qs.backend == "piqp":
            z, iters, status = _solve_piqp(qs, data, cfg)
        elif qs.backend == "daqp":
            if qs.solver is None:
                from .condensed import CondensedDAQP  # imported on use, as is the daqp package
                qs.solver = CondensedDAQP(qs)
            z, iters, status = qs.solver.solve(qs, data)
        else:
            z, iters, status = _solve_osqp(qs, data)
    except (RuntimeError, ValueError, ArithmeticError) as exc:
        qs.drop_solver()  # set up afresh next time
        return None, 0, f"{qs.backend} raised {exc}"
    if z is None:
        qs.drop_solver()  # a fresh set-up (and scaling) next time
        return None, iters, status
    if not all_finite(z):
        return None, iters, f"{qs.backend} returned non-finite values"
    return z, iters, "solved"


def _solve_fallback(qs: QPStructure, data: tuple) -> tuple[np.ndarray | None, int, str]:
    """The QP by the condensed DAQP backend (``MPCConfig.qp_fallback``), its model kept in ``qs.fallback``."""
    try:
        if qs.fallback is None:
            from .condensed import CondensedDAQP

            qs.fallback = CondensedDAQP(qs)
        z, iters, status = qs.fallback.solve(qs, data)
    except (RuntimeError, ValueError, ArithmeticError) as exc:
        qs.fallback = None
        return None, 0, f"daqp raised {exc}"
    if z is None:
        qs.fallback = None
        return None, iters, status
    if not all_finite(z):
        return None, iters, "daqp returned non-finite values"
    return z, iters, "solved"


def dcbf_margin(qs: QPStructure, z: np.ndarray, hu: np.ndarray) -> np.ndarray:
    """``h_u - G z`` of the DCBF rows at the solution ``z`` (for PIQP: as PIQP computed it, unless the fallback
    backend solved this QP, after which the structure has no PIQP solver)."""
    rows = qs.cbf_rows
    if qs.backend == "piqp" and qs.solver is not None:
        return qs.solver.result.s_u[rows]
    g = qs.G
    return _csc_margin(g.data, g.indices, g.indptr, z, hu, rows)


@kernel
def _csc_margin(data, indices, indptr, z, hu, rows):
    """``hu[rows] - (G @ z)[rows]`` for ``G`` in CSC form (``data, indices, indptr``), to the bit: the product
    accumulated from zero column by column, as scipy's ``csc_matvec`` does."""
    y = np.zeros(hu.shape[0])
    for j in range(indptr.shape[0] - 1):
        zj = z[j]
        for p in range(indptr[j], indptr[j + 1]):
            y[indices[p]] += data[p] * zj
    out = np.empty(rows.shape[0])
    for r in range(rows.shape[0]):
        out[r] = hu[rows[r]] - y[rows[r]]
    return out


def _solve_piqp(qs: QPStructure, data: tuple, cfg: MPCConfig):
    c, b, hl, hu, xl, xu = data
    if qs.solver is None and qs.solver_setup is None:  # a fresh set-up on these data
        qs.solver_setup = (c.copy(), qs.A.data.copy(), b.copy(), qs.G.data.copy(), hl.copy(), hu.copy(),
                           xl.copy(), xu.copy())
        qs.solver_updates = 0
        qs.solver = _setup_piqp(qs, qs.solver_setup, cfg)
    else:
        if qs.solver is None:  # a copied structure: the original's set-up and as many updates
            qs.solver = _setup_piqp(qs, qs.solver_setup, cfg)
            for _ in range(qs.solver_updates):
                qs.solver.update()
        qs.solver.update(c=c, A=qs.A, b=b, G=qs.G, h_l=hl, h_u=hu, x_l=xl, x_u=xu)
        qs.solver_updates += 1
    status = qs.solver.solve()
    res = qs.solver.result
    iters = int(res.info.iter)
    if status != piqp.PIQP_SOLVED:
        return None, iters, f"piqp status {status}"
    return np.array(res.x), iters, "solved"


def _setup_piqp(qs: QPStructure, setup: tuple, cfg: MPCConfig) -> piqp.SparseSolver:
    """A PIQP instance set up on ``setup`` (``QPStructure.solver_setup``: c, A values, b, G values, h_l, h_u,
    x_l, x_u) in the pattern of ``qs``."""
    c, a_values, b, g_values, hl, hu, xl, xu = setup
    solver = piqp.SparseSolver()
    st = solver.settings
    st.verbose = False
    st.eps_abs = cfg.qp_eps_abs
    st.eps_rel = cfg.qp_eps_rel
    st.check_duality_gap = False
    st.preconditioner_scale_cost = True  # without it some cold-start QPs stall
    # The QP is feasible and bounded by construction (soft constraints, consistent boxes,
    # R > 0, Z > 0; checked before the call); PIQP's infeasibility tests misfire on it.
    st.eps_primal_inf = 1e-12
    st.eps_dual_inf = 1e-12
    # the data change little from step to step: keeping the first scaling saves ~130 us per update
    st.preconditioner_reuse_on_update = True
    st.max_iter = cfg.qp_max_iter
    a_mat = sp.csc_matrix((a_values, qs.A.indices, qs.A.indptr), shape=qs.A.shape)
    g_mat = sp.csc_matrix((g_values, qs.G.indices, qs.G.indptr), shape=qs.G.shape)
    solver.setup(qs.P, c, a_mat, b, g_mat, hl, hu, xl, xu)
    return solver


def _solve_osqp(qs: QPStructure, data: tuple):
    import osqp  # imported on use: comparison only, and its import takes ~0.3 s

    c, b, hl, hu, xl, xu = data
    big = 1e20  # OSQP's infinity is 1e30; clip the infinite bounds below it
    lo = np.concatenate([b, np.maximum(hl, -big), np.maximum(xl, -big)])
    up = np.concatenate([b, np.minimum(hu, big), np.minimum(xu, big)])
    mat = sp.vstack([qs.A, qs.G, sp.identity(qs.nz, format="csc")], format="csc")
    if qs.solver is None or qs.osqp_mat is None or mat.nnz != qs.osqp_mat.nnz:
        solver = osqp.OSQP()
        solver.setup(sp.triu(qs.P, format="csc"), c, mat, lo, up, verbose=False, eps_abs=1e-4,
                     eps_rel=1e-4, max_iter=4000, polishing=False, warm_starting=True)
        qs.solver = solver
        qs.osqp_mat = mat
    else:
        qs.solver.update(q=c, l=lo, u=up, Ax=mat.data)
    res = qs.solver.solve(raise_error=False)
    iters = int(res.info.iter)
    if res.info.status_val not in (osqp.SolverStatus.OSQP_SOLVED, osqp.SolverStatus.OSQP_SOLVED_INACCURATE):
        return None, iters, f"osqp status {res.info.status}"
    return np.array(res.x), iters, "solved"
