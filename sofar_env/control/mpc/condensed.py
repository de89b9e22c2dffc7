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

Each :class:`~.layout.QPStructure` keeps one :class:`CondensedDAQP` as its solver: a
:class:`daqp.Model` set up once per pattern and updated with the new matrices. Every solve starts from
the empty working set (``sense`` given anew): with daqp 0.11, starting from the previous solve's working
set (the update without ``sense``, or ``sense`` with the active flags of the last multipliers) returned
non-finite solutions with exit flag 1 on closed-loop QPs of this controller. A status other than
optimal (1) or soft-optimal (2), data outside this contract (ValueError) or a non-finite solution drop
the model (the next solve sets up afresh) and are reported as a failure (-> fallback), as with the other
backends (:func:`~.backends.solve_qp`).

Accuracy and cost (``bench/bench_qp_backends.py``, 309 QPs of a 300-step closed loop, against PIQP at
tolerances 1e-11): first input within 4e-8, plan within 3e-7 (PIQP at its defaults: 5e-6 and 5e-3);
CPU time per solve median 0.18 ms against PIQP's 0.16 ms (p95 0.26 against 0.29 ms): about 0.05 ms the
condensing (one compiled kernel, :func:`_condense`, compiled on first use and cached as the package's other
kernels), 0.05 ms DAQP's update and solve.
"""

from __future__ import annotations

import daqp
import numpy as np

from ..._jit import kernel
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
def _condense(ad, g_csr, qp, p, layout, out):
    """The condensed QP (module docstring) into the output arrays (``amat``, ``lo_rows``, ``go``, ``rho``, ``w``
    prefilled by the caller); returns 0, or the contract the data break: 1 (a dx_{k+1} factor other than 1),
    2 (a soft pair: signs, infinite sides or rows differ), 3 (a single soft row's other side is finite),
    4 (a soft slack's bounds are not [0, inf)).

    The inputs, one bundle per concept: ``ad`` the equality rows (dense); ``g_csr`` ``(data, indices, indptr)``
    of G; ``qp`` the sparse QP's vectors ``(c, b, hl, hu, xl, xu)``; ``p`` the cost's diagonal; ``layout`` the
    pattern's index arrays ``(u_cols, x_cols, var_cols, kind, idx, hard_rows, soft_cols, soft_up, soft_lo,
    row_out, row_lo)``; ``out`` ``(sol, hess, f, amat, lo_rows, go, bu, bl, rho, w, gabs)``, written.

    ``sol`` (5N, 2N + 1): ``dx = sol[:, :2N] du + sol[:, 2N]``, by block forward substitution through the
    equality rows ``ad``, whose dx_k entries sit in the block below the diagonal. ``kind``/``idx`` per
    column of z: 0 an input (its index), 1 a state (its row of ``sol``), 2 an explicit slack (its variable),
    3 a soft slack. ``row_out``/``row_lo`` per row of G: its row of ``amat`` (or -1) and, for the lower row of
    a soft pair, its row of ``lo_rows`` (checked equal to the upper one's)."""
    g_data, g_ind, g_ptr = g_csr
    c, b, hl, hu, xl, xu = qp
    u_cols, x_cols, var_cols, kind, idx, hard_rows, soft_cols, soft_up, soft_lo, row_out, row_lo = layout
    sol, hess, f, amat, lo_rows, go, bu, bl, rho, w, gabs = out
    nu = len(u_cols)
    nx = len(x_cols)
    nv = hess.shape[0]
    for r in range(nx):
        k = r // 5
        if ad[r, x_cols[r]] != 1.0:
            return 1
        for j in range(nu + 1):
            acc = -ad[r, u_cols[j]] if j < nu else b[r]
            if k > 0:
                for q in range(5 * (k - 1), 5 * k):
                    acc -= ad[r, x_cols[q]] * sol[q, j]
            sol[r, j] = acc
    # H = Tz' diag(p) Tz (here its diagonal from the identity blocks), f = Tz' (p t0 + c); input i acts on
    # the states from stage i // 2 on
    for i in range(nv):
        for j in range(nv):
            hess[i, j] = 0.0
        f[i] = c[var_cols[i]]
    for i in range(nu):  # (the inputs' block of H, sol' diag(p) sol, is added by the caller with BLAS)
        acc = 0.0
        for r in range(5 * (i // 2), nx):
            acc += sol[r, i] * (p[x_cols[r]] * sol[r, nu] + c[x_cols[r]])
        f[i] += acc
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


class CondensedDAQP:
    """The condensed QP of one :class:`~.layout.QPStructure` and its DAQP model (module docstring)."""

    def __init__(self, qs):
        nb, nz = qs.nb, qs.nz
        n_h = nz // nb
        blk = np.arange(n_h) * nb
        self.u_cols = (blk[:, None] + np.arange(2)[None, :]).ravel()
        self.x_cols = (blk[:, None] + 2 + np.arange(5)[None, :]).ravel()
        g = qs.G.tocsc()
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
        self.model: daqp.Model | None = None

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
        every constraint; ``sol``, ``go``, ``gabs`` what maps the solution back (:meth:`solve`). Raises
        ValueError for data outside the contract (:func:`_condense`)."""
        nu, nv, nx = len(self.u_cols), self.nv, len(self.x_cols)
        n_rows = len(self.sense) - nv
        out = (np.empty((nx, nu + 1)), np.empty((nv, nv)), np.empty(nv), np.zeros((n_rows, nv)),
               np.zeros((len(self.soft_cols), nv)), np.zeros(qs.n_in), np.empty(nv + n_rows), np.empty(nv + n_rows),
               np.full(nv + n_rows, 1e-6), np.zeros(nv + n_rows), np.empty(len(self.soft_cols)))
        sol, hess, f, amat, lo_rows, go, bu, bl, rho, w, gabs = out
        g = qs.G
        layout = (self.u_cols, self.x_cols, self.var_cols, self.kind, self.idx, self.hard_rows, self.soft_cols,
                  self.soft_up, self.soft_lo, self.row_out, self.row_lo)
        status = _condense(qs.A.toarray(), (g.data, g.indices, g.indptr), tuple(data), self.p, layout, out)
        if status:
            raise ValueError(f"QP data outside the condensing contract ({_CONTRACT[status]})")
        sx = sol[:, :nu]
        hess[:nu, :nu] += sx.T @ (self.p[self.x_cols][:, None] * sx)
        return hess, f, amat, bu, bl, rho, w, sol, go, gabs

    def solve(self, qs, data: tuple) -> tuple[np.ndarray | None, int, str]:
        """``(z or None, iterations, message)``; raises only ValueError / RuntimeError for the caller
        (:func:`~.backends.solve_qp`) to map to a failure."""
        hess, f, amat, bu, bl, rho, w, sol, go, gabs = self.condense(qs, data)
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
        iters = int(info["iterations"])
        if flag not in _OK:
            return None, iters, f"daqp exit flag {flag}"
        v = np.asarray(v, dtype=float)
        if not np.all(np.isfinite(v)):
            return None, iters, f"daqp returned non-finite values (exit flag {flag})"
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
