"""The RTI's QP condensed onto its inputs and solved by DAQP (dense active set): ``qp_solver = "daqp"``.

The same problem as the sparse QP of :class:`~.layout.QPStructure` (same cost, rows, slacks and
bounds), in other variables:

* the states are eliminated through the equality rows ``dx_{k+1} - A_k dx_k - B_k du_k = b_k``
  (``dx_0 = 0``): ``(du_k, dx_{k+1})_k = T du + t`` with ``du`` the ``2 N`` input steps (40 at N = 20);
* a slack column whose rows are one row (a DCBF row) or a pair of rows with the same coefficients that
  bound it from above and from below (the lateral-acceleration rows, the track rows of the reference
  point) becomes a DAQP soft constraint (``sense`` 8) with that row's own weights: DAQP adds
  ``w s + s^2 / (2 rho)`` for the violation ``s >= 0`` of a soft row in the row's units
  (:meth:`daqp.Model.soft_weights`, checked against closed forms in the tests), so the slack's cost
  ``c sigma~ + p sigma~^2 / 2`` of the sparse QP, with ``s = g sigma~`` (``g`` the slack's coefficient
  in the row), is ``w = c / g`` and ``rho = g^2 / p``;
* a slack shared by rows with different coefficients (the four end rows of ``track_rows = "ends"`` /
  ``"recoverable"``: one slack is the largest violation of the four, not a sum) stays an explicit
  decision variable after the inputs, with its bounds and cost as in the sparse QP.

The box bounds on ``du`` (and on explicit slacks) are DAQP's simple bounds; those on ``dx`` are general
rows of ``T``. Infinite bounds stay infinite (inactive). The solution is mapped back to the sparse
variables ``z`` (states from ``T``, soft slacks as the violation of their rows divided by ``g``), so the
controller treats every backend alike.

Each :class:`~.layout.QPStructure` keeps one :class:`CondensedDAQP` as its solver. Every solve starts from
the empty working set (``sense`` given anew): with daqp 0.11, starting from the previous solve's working
set (the update without ``sense``, or ``sense`` with the active flags of the last multipliers) returned
non-finite solutions with exit flag 1 on closed-loop QPs of this controller. Two routes, the same solution
to the bit (tests/control/mpc/test_condensed_c.py):

* compiled (with :data:`~sofar_env.planning.daqp_c.SOFT_AVAILABLE`, the pinned daqp): one kernel,
  :func:`_solve_compact`, drops the rows with both bounds infinite (the box rows of most states: about 100 of
  140; such a row can never enter DAQP's working set, and on every recorded QP the solution is the same to the
  bit without it), then sets up, solves and frees DAQP's workspace through its C calls
  (:func:`~sofar_env.planning.daqp_c.soft_solve`);
* otherwise a :class:`daqp.Model` set up once per pattern and updated with the new matrices.

A status other than optimal (1) or soft-optimal (2), data outside this contract (ValueError) or a non-finite
solution drop the solver (the next solve sets up afresh) and are reported as a failure (-> fallback), as with
the other backends (:func:`~.backends.solve_qp`).

Accuracy and cost (``bench/bench_qp_backends.py``, 309 QPs of a 300-step closed loop, against PIQP at
tolerances 1e-11): first input within 4e-8, plan within 3e-7 (PIQP at its defaults: 5e-6 and 5e-3);
CPU time per solve of the :class:`daqp.Model` route median 0.18 ms against PIQP's 0.16 ms (p95 0.26
against 0.29 ms): about 0.05 ms the condensing (one compiled kernel, :func:`_condense`, compiled on first use
and cached as the package's other kernels), 0.05 ms DAQP's update and solve; the compiled route's numbers are
in docs/decisions/qp-backend.md.
"""

from __future__ import annotations

import daqp
import numpy as np

from ..._jit import kernel
from ...planning import daqp_c
from .assembly import all_finite
from .layout import N_FIXED

__all__ = ["CondensedDAQP", "DAQP_ITER_LIMIT", "DAQP_PRIMAL_TOL"]

DAQP_PRIMAL_TOL = 1e-9
"""DAQP's primal feasibility tolerance (an active-set solution is exact up to it and to rounding)."""
DAQP_ITER_LIMIT = 2000
"""DAQP's iteration limit: one iteration adds or removes one constraint of the working set."""
_SOFT = 8
_OK = (1, 2)  # optimal, soft-optimal
_CONTRACT = {1: "dx_{k+1} with a factor other than 1", 2: "a soft row pair", 3: "a single soft row",
             4: "a soft slack's bounds"}


@kernel
def _condense(a_csc, g_csr, qp, p, layout, out):
    """The condensed QP (module docstring) into the output arrays, every entry written; returns 0, or the
    contract the data break: 1 (a dx_{k+1} factor other than 1), 2 (a soft pair: signs, infinite sides or rows
    differ), 3 (a single soft row's other side is finite), 4 (a soft slack's bounds are not [0, inf)).

    The inputs, one bundle per concept: ``a_csc`` ``(data, indices, indptr)`` of the equality rows A (CSC,
    canonical), their entries in ``ad`` (nx, nu + 6) as ``A.toarray()`` has them (below); ``g_csr``
    ``(data, indices, indptr)`` of G; ``qp`` the sparse QP's vectors ``(c, b, hl, hu, xl, xu)``; ``p`` the cost's
    diagonal; ``layout`` the pattern's index arrays ``(u_cols, x_cols, var_cols, kind, idx, hard_rows, soft_cols,
    soft_up, soft_lo, row_out, row_lo)``; ``out`` ``(ad, sol, hess, f, amat, lo_rows, go, bu, bl, rho, w, gabs)``,
    written.

    ``sol`` (5N, 2N + 1): ``dx = sol[:, :2N] du + sol[:, 2N]``, by block forward substitution through the
    equality rows ``ad``, whose dx_k entries sit in the block below the diagonal. ``kind``/``idx`` per
    column of z: 0 an input (its index), 1 a state (its row of ``sol``), 2 an explicit slack (its variable),
    3 a soft slack. ``row_out``/``row_lo`` per row of G: its row of ``amat`` (or -1) and, for the lower row of
    a soft pair, its row of ``lo_rows`` (checked equal to the upper one's)."""
    g_data, g_ind, g_ptr = g_csr
    a_data, a_ind, a_ptr = a_csc
    c, b, hl, hu, xl, xu = qp
    u_cols, x_cols, var_cols, kind, idx, hard_rows, soft_cols, soft_up, soft_lo, row_out, row_lo = layout
    ad, sol, hess, f, amat, lo_rows, go, bu, bl, rho, w, gabs = out
    nu = len(u_cols)
    nx = len(x_cols)
    nv = hess.shape[0]
    # A's entries as A.toarray() has them (each added to a zero), compact: ad[r, :nu] the inputs' columns,
    # ad[r, nu + q % 5] the previous stage's states q, ad[r, nu + 5] the diagonal dx_{k+1} (the only columns
    # the constructor allows)
    ad[:, :] = 0.0
    for col in range(len(kind)):
        for e in range(a_ptr[col], a_ptr[col + 1]):
            r = a_ind[e]
            if kind[col] == 0:
                ad[r, idx[col]] += a_data[e]
            elif idx[col] == r:
                ad[r, nu + 5] += a_data[e]
            else:
                ad[r, nu + idx[col] % 5] += a_data[e]
    amat[:, :] = 0.0
    lo_rows[:, :] = 0.0
    go[:] = 0.0
    rho[:] = 1e-6  # DAQP's default weight where a row is not soft (unused there)
    w[:] = 0.0
    # (each entry's sums below run in a fixed order, the same as a loop over that entry alone: the loops are
    # ordered for contiguous rows, which changes no bit without fastmath)
    for r in range(nx):
        k = r // 5
        if ad[r, nu + 5] != 1.0:
            return 1
        for j in range(nu):
            sol[r, j] = -ad[r, j]
        sol[r, nu] = b[r]
        if k > 0:
            for q in range(5 * (k - 1), 5 * k):
                a_rq = ad[r, nu + q % 5]
                for j in range(nu + 1):
                    sol[r, j] -= a_rq * sol[q, j]
    # H = Tz' diag(p) Tz (here its diagonal from the identity blocks), f = Tz' (p t0 + c); input i acts on
    # the states from stage i // 2 on, i.e. state row r on the inputs i < 2 (r // 5 + 1)
    for i in range(nv):
        for j in range(nv):
            hess[i, j] = 0.0
        f[i] = c[var_cols[i]]
    acc = np.zeros(nu)  # (the inputs' block of H, sol' diag(p) sol, is added by the caller with BLAS)
    for r in range(nx):
        t_r = p[x_cols[r]] * sol[r, nu] + c[x_cols[r]]
        for i in range(min(nu, 2 * (r // 5 + 1))):
            acc[i] += sol[r, i] * t_r
    for i in range(nu):
        f[i] += acc[i]
    for i in range(nv):
        hess[i, i] += p[var_cols[i]]
        bu[i] = xu[var_cols[i]]
        bl[i] = xl[var_cols[i]]
    # rows: the box on dx, then the rows of G (soft slack columns left out)
    for r in range(nx):
        for j in range(nu):
            amat[r, j] = sol[r, j]
        bu[nv + r] = xu[x_cols[r]] - sol[r, nu]
        bl[nv + r] = xl[x_cols[r]] - sol[r, nu]
    for col in range(len(kind)):
        kd = kind[col]
        if kd == 3:
            continue
        for e in range(g_ptr[col], g_ptr[col + 1]):
            row = g_ind[e]
            val = g_data[e]
            tgt = amat[row_out[row]] if row_out[row] >= 0 else lo_rows[row_lo[row]]
            if kd == 1:
                rs = idx[col]
                for j in range(nu):
                    tgt[j] += val * sol[rs, j]
                go[row] += val * sol[rs, nu]
            else:
                tgt[idx[col]] += val
    for h in range(len(hard_rows)):
        row = hard_rows[h]
        bu[nv + row_out[row]] = hu[row] - go[row]
        bl[nv + row_out[row]] = hl[row] - go[row]
    for s in range(len(soft_cols)):
        col = soft_cols[s]
        up = soft_up[s]
        lo = soft_lo[s]
        g_up = 0.0
        g_lo = 0.0
        for e in range(g_ptr[col], g_ptr[col + 1]):
            if g_ind[e] == up:
                g_up = g_data[e]
            if g_ind[e] == lo:
                g_lo = g_data[e]
        o = row_out[up]
        if up != lo:
            if not (g_up < 0.0 and g_lo == -g_up and hl[up] == -np.inf and hu[lo] == np.inf and go[up] == go[lo]):
                return 2
            for j in range(nv):
                if amat[o, j] != lo_rows[row_lo[lo], j]:
                    return 2
        elif not ((g_up < 0.0 and hl[up] == -np.inf) or (g_up > 0.0 and hu[up] == np.inf)):
            return 3
        if not (xl[col] == 0.0 and xu[col] == np.inf):
            return 4
        gabs[s] = abs(g_up)
        bu[nv + o] = hu[up] - go[up]
        bl[nv + o] = hl[lo] - go[lo]
        rho[nv + o] = gabs[s] * gabs[s] / p[col]
        w[nv + o] = c[col] / gabs[s]
    return 0


@kernel
def _solve_compact(hess, f, amat, bu, bl, sense, rho, w, compact, records, buffers, work, slot):
    """:func:`~sofar_env.planning.daqp_c.soft_solve` of the condensed QP without its rows whose bounds are both
    infinite (module docstring): ``compact`` ``(A, bupper, blower, sense, rho, w)`` buffers of the full size,
    written. Returns ``soft_solve``'s ``(setup_flag, exitflag, iterations)``; the solution is in
    ``buffers[0][:n]``."""
    a_c, bu_c, bl_c, sense_c, rho_c, w_c = compact
    nv = f.shape[0]
    for i in range(nv):
        bu_c[i] = bu[i]
        bl_c[i] = bl[i]
        sense_c[i] = sense[i]
        rho_c[i] = rho[i]
        w_c[i] = w[i]
    k = 0
    for r in range(amat.shape[0]):
        i = nv + r
        if bu[i] == np.inf and bl[i] == -np.inf:
            continue
        for j in range(nv):
            a_c[k, j] = amat[r, j]
        bu_c[nv + k] = bu[i]
        bl_c[nv + k] = bl[i]
        sense_c[nv + k] = sense[i]
        rho_c[nv + k] = rho[i]
        w_c[nv + k] = w[i]
        k += 1
    m = nv + k
    return daqp_c.soft_solve(hess, f, a_c[:k], bu_c[:m], bl_c[:m], sense_c[:m], rho_c[:m], w_c[:m], records,
                             buffers, work, slot)


class CondensedDAQP:
    """The condensed QP of one :class:`~.layout.QPStructure` and its DAQP model (module docstring)."""

    def __init__(self, qs):
        nb, nz = qs.nb, qs.nz
        n_h = nz // nb
        blk = np.arange(n_h) * nb
        self.u_cols = (blk[:, None] + np.arange(2)[None, :]).ravel()
        self.x_cols = (blk[:, None] + 2 + np.arange(5)[None, :]).ravel()
        g = qs.G.tocsc()
        if qs.A.format != "csc" or not qs.A.has_canonical_format:
            raise RuntimeError("equality rows not in canonical CSC form")  # construction bug (read as CSC)
        a_coo = qs.A.tocoo()
        if not np.all(np.isin(a_coo.col, np.concatenate([self.u_cols, self.x_cols]))):
            raise RuntimeError("equality rows on slack columns")  # construction bug
        # dx entries of the equality rows: dx_{k+1} itself (diagonal) and dx_k (the block below it)
        x_pos = np.searchsorted(self.x_cols, a_coo.col[np.isin(a_coo.col, self.x_cols)])
        x_row = a_coo.row[np.isin(a_coo.col, self.x_cols)]
        if not np.all((x_pos == x_row) | (x_pos // 5 == x_row // 5 - 1)):
            raise RuntimeError("equality rows outside the stage recursion")  # construction bug
        # slack columns: soft (one row, or an upper/lower pair of equal rows) or explicit
        soft_rows, soft_cols, explicit = [], [], []
        for j in (blk[:, None] + np.arange(N_FIXED, nb)[None, :]).ravel():
            rows = g.indices[g.indptr[j]:g.indptr[j + 1]]
            if len(rows) == 1 or (len(rows) == 2 and self._same_pattern(g, rows[0], rows[1])):
                soft_rows.append((rows[0], rows[-1]))
                soft_cols.append(j)
            else:
                explicit.append(j)
        self.soft_cols = np.array(soft_cols, dtype=np.int64)
        self.soft_rows = np.array(soft_rows, dtype=np.int64).reshape(-1, 2)
        self.expl_cols = np.array(explicit, dtype=np.int64)
        soft_set = set(self.soft_rows.ravel().tolist())
        self.hard_rows = np.array([r for r in range(qs.n_in) if r not in soft_set], dtype=np.int64)
        self.var_cols = np.concatenate([self.u_cols, self.expl_cols])  # decision variables, in order
        self.nv = len(self.var_cols)
        self.p = qs.P.diagonal().copy()
        # the upper row of a soft pair: the one its slack relaxes from above (coefficient < 0), by the
        # current data (checked per solve)
        sign = {}
        for j in self.soft_cols:
            for e in range(g.indptr[j], g.indptr[j + 1]):
                sign[(j, g.indices[e])] = g.data[e]
        self.soft_up = np.array([r0 if (r0 == r1 or sign[(j, r0)] < 0.0) else r1
                                 for j, (r0, r1) in zip(self.soft_cols, self.soft_rows)], dtype=np.int64)
        self.soft_lo = np.where(self.soft_up == self.soft_rows[:, 0], self.soft_rows[:, 1], self.soft_rows[:, 0])
        nx, nh, ns = len(self.x_cols), len(self.hard_rows), len(self.soft_cols)
        self.row_out = np.full(qs.n_in, -1, dtype=np.int64)
        self.row_out[self.hard_rows] = nx + np.arange(nh)
        self.row_out[self.soft_up] = nx + nh + np.arange(ns)
        self._soft_out = nx + nh + np.arange(ns)
        self.row_lo = np.full(qs.n_in, -1, dtype=np.int64)
        pair = self.soft_lo != self.soft_up
        self.row_lo[self.soft_lo[pair]] = np.flatnonzero(pair)
        self.kind = np.full(nz, 3, dtype=np.int64)
        self.idx = np.zeros(nz, dtype=np.int64)
        self.kind[self.u_cols], self.idx[self.u_cols] = 0, np.arange(len(self.u_cols))
        self.kind[self.x_cols], self.idx[self.x_cols] = 1, np.arange(nx)
        self.kind[self.expl_cols], self.idx[self.expl_cols] = 2, len(self.u_cols) + np.arange(len(self.expl_cols))
        n_rows = nx + nh + ns
        self.sense = np.zeros(self.nv + n_rows, dtype=np.int32)
        self.sense[self.nv + n_rows - ns:] = _SOFT
        self._p_x = self.p[self.x_cols][:, None]
        self._layout = (self.u_cols, self.x_cols, self.var_cols, self.kind, self.idx, self.hard_rows,
                        self.soft_cols, self.soft_up, self.soft_lo, self.row_out, self.row_lo)
        nu, nv, n_in = len(self.u_cols), self.nv, qs.n_in
        self._out = (np.zeros((nx, nu + 6)), np.empty((nx, nu + 1)), np.empty((nv, nv)), np.empty(nv),
                     np.zeros((n_rows, nv)), np.zeros((ns, nv)), np.zeros(n_in), np.empty(nv + n_rows),
                     np.empty(nv + n_rows), np.empty(nv + n_rows), np.empty(nv + n_rows), np.empty(ns))
        """The condensed QP's arrays (:func:`_condense`'s ``out``), rewritten by every :meth:`condense`."""
        self.model: daqp.Model | None = None
        self.native: daqp_c.Workspace | None = None
        """The compiled route's DAQP records and buffers (None: the :class:`daqp.Model` route)."""
        if daqp_c.SOFT_AVAILABLE:
            self.native = daqp_c.Workspace(self.nv, self.nv + n_rows)
            settings = self.native.records[1][0]
            settings["primal_tol"], settings["iter_limit"] = DAQP_PRIMAL_TOL, DAQP_ITER_LIMIT
            m = self.nv + n_rows
            self._compact = (np.zeros((n_rows, self.nv)), np.empty(m), np.empty(m), np.empty(m, dtype=np.int32),
                             np.empty(m), np.empty(m))

    @staticmethod
    def _same_pattern(g, r0: int, r1: int) -> bool:
        """Rows ``r0`` and ``r1`` of ``g`` have the same columns (their values are checked per solve)."""
        gr = g.tocsr()
        c0 = gr.indices[gr.indptr[r0]:gr.indptr[r0 + 1]]
        c1 = gr.indices[gr.indptr[r1]:gr.indptr[r1 + 1]]
        return np.array_equal(np.sort(c0), np.sort(c1))

    # ------------------------------------------------------------------ solve

    def condense(self, qs, data: tuple) -> tuple:
        """``(H, f, A, bupper, blower, rho, w, sol, go, gabs)`` of the condensed QP (module docstring): simple
        bounds first, then the rows on dx, the hard rows and the soft rows; ``rho``, ``w`` the soft weights of
        every constraint; ``sol``, ``go``, ``gabs`` what maps the solution back (:meth:`solve`). The arrays are
        this object's, rewritten by the next call. Raises ValueError for data outside the contract
        (:func:`_condense`)."""
        out = self._out
        a, g = qs.A, qs.G
        status = _condense((a.data, a.indices, a.indptr), (g.data, g.indices, g.indptr), tuple(data), self.p,
                           self._layout, out)
        if status:
            raise ValueError(f"QP data outside the condensing contract ({_CONTRACT[status]})")
        _, sol, hess, f, amat, _, go, bu, bl, rho, w, gabs = out
        nu = len(self.u_cols)
        sx = sol[:, :nu]
        hess[:nu, :nu] += sx.T @ (self._p_x * sx)
        return hess, f, amat, bu, bl, rho, w, sol, go, gabs

    def solve(self, qs, data: tuple) -> tuple[np.ndarray | None, int, str]:
        """``(z or None, iterations, message)``; raises only ValueError / RuntimeError for the caller
        (:func:`~.backends.solve_qp`) to map to a failure."""
        hess, f, amat, bu, bl, rho, w, sol, go, gabs = self.condense(qs, data)
        if self.native is not None:
            v, iters, fail = self._solve_native(hess, f, amat, bu, bl, rho, w)
        else:
            v, iters, fail = self._solve_model(hess, f, amat, bu, bl, rho, w)
        if fail:
            return None, iters, fail
        nu = len(self.u_cols)
        z = np.zeros(qs.nz)
        z[self.u_cols] = v[:nu]
        z[self.x_cols] = sol[:, :nu] @ v[:nu] + sol[:, nu]
        z[self.expl_cols] = v[nu:]
        # soft slacks: the violation of their row (the sparse QP's optimal slack), in sigma~ units
        _, _, hl, hu, _, _ = data
        up, lo = self.soft_up, self.soft_lo
        r = amat[self._soft_out] @ v + go[up]
        z[self.soft_cols] = np.maximum(np.maximum(r - hu[up], hl[lo] - r), 0.0) / gabs
        return z, iters, "solved"

    def _solve_native(self, hess, f, amat, bu, bl, rho, w) -> tuple[np.ndarray | None, int, str]:
        """``(v, iterations, failure message or "")`` by the compiled route (module docstring)."""
        ws = self.native
        setup, flag, iters = _solve_compact(hess, f, amat, bu, bl, self.sense, rho, w, self._compact, ws.records,
                                            ws.buffers, ws.work, daqp_c.SETTINGS_SLOT)
        if setup <= 0:
            return None, 0, f"daqp setup exit flag {setup}" if setup < 0 else "daqp without per-row soft weights"
        return self._checked(ws.buffers[0][:self.nv].copy(), int(flag), int(iters))

    @staticmethod
    def _checked(v: np.ndarray, flag: int, iters: int) -> tuple[np.ndarray | None, int, str]:
        if flag not in _OK:
            return None, iters, f"daqp exit flag {flag}"
        if not all_finite(v):
            return None, iters, f"daqp returned non-finite values (exit flag {flag})"
        return v, iters, ""

    def _solve_model(self, hess, f, amat, bu, bl, rho, w) -> tuple[np.ndarray | None, int, str]:
        """``(v, iterations, failure message or "")`` by the :class:`daqp.Model` route (module docstring)."""
        if self.model is None:
            self.model = daqp.Model()
            flag, _ = self.model.setup(hess, f, amat, bu, bl, self.sense.copy())
            if flag < 0:
                self.model = None
                return None, 0, f"daqp setup exit flag {flag}"
            self.model.settings = {"primal_tol": DAQP_PRIMAL_TOL, "iter_limit": DAQP_ITER_LIMIT}
        else:
            flag = self.model.update(H=hess, f=f, A=amat, bupper=bu, blower=bl, sense=self.sense.copy())
            if flag < 0:
                return None, 0, f"daqp update exit flag {flag}"
        self.model.soft_weights(rho_l=rho, rho_u=rho, w_l=w, w_u=w)
        v, _, flag, info = self.model.solve()
        return self._checked(np.asarray(v, dtype=float), int(flag), int(info["iterations"]))
