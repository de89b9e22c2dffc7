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

Accuracy and cost (``eval/bench_qp_backends.py``, 309 QPs of a 300-step closed loop, against PIQP at
tolerances 1e-11): first input within 4e-8, plan within 3e-7 (PIQP at its defaults: 5e-6 and 5e-3);
CPU time per solve about twice PIQP's (median 0.32 ms against 0.17 ms), most of it the condensing.
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


@kernel
def _eliminate(ex, rhs, out):
    """``out = ex^-1 rhs`` for ``ex`` with identity 5x5 diagonal blocks and blocks below them only (the
    equality rows' dx columns): block forward substitution, stage by stage."""
    n = ex.shape[0] // 5
    for k in range(n):
        for i in range(5):
            r = 5 * k + i
            for j in range(rhs.shape[1]):
                acc = rhs[r, j]
                if k > 0:
                    for q in range(5):
                        acc -= ex[r, 5 * (k - 1) + q] * out[5 * (k - 1) + q, j]
                out[r, j] = acc


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
        self._diag = (np.arange(len(self.x_cols)), np.arange(len(self.x_cols)))
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
        self._vdiag = (np.arange(self.nv), np.arange(self.nv))
        # positions in G.data of the soft slacks' entries, and of each soft row's first and last one there
        first = g.indptr[self.soft_cols]
        count = g.indptr[self.soft_cols + 1] - first
        self._soft_data = np.concatenate([np.arange(a, a + n) for a, n in zip(first, count)]).astype(np.int64) \
            if len(first) else np.zeros(0, dtype=np.int64)
        self._soft_first = np.concatenate([[0], np.cumsum(count)[:-1]]).astype(np.int64) if len(first) else first
        self._soft_last = self._soft_first + count - 1
        n_rows = len(self.x_cols) + len(self.hard_rows) + len(self.soft_rows)
        self.sense = np.zeros(self.nv + n_rows, dtype=np.int32)
        self.sense[self.nv + n_rows - len(self.soft_rows):] = _SOFT
        self.model: daqp.Model | None = None

    @staticmethod
    def _same_pattern(g, r0: int, r1: int) -> bool:
        """Rows ``r0`` and ``r1`` of ``g`` have the same columns (their values are checked per solve)."""
        gr = g.tocsr()
        c0 = gr.indices[gr.indptr[r0]:gr.indptr[r0 + 1]]
        c1 = gr.indices[gr.indptr[r1]:gr.indptr[r1 + 1]]
        return np.array_equal(np.sort(c0), np.sort(c1))

    # ------------------------------------------------------------------ condensing

    def condense(self, qs, data: tuple):
        """``(H, f, A, bupper, blower, rho, w, back)`` of the condensed QP (module docstring): simple bounds
        first, then the rows on dx, the hard rows and the soft rows; ``rho``, ``w`` the soft rows' weights;
        ``back`` what maps the solution to ``z`` (:meth:`solve`). Raises ValueError for data outside the
        contract (a soft pair whose rows differ, a soft slack with a finite upper bound)."""
        c, b, hl, hu, xl, xu = data
        nz = qs.nz
        ad = qs.A.toarray()
        ex = ad[:, self.x_cols]
        if not np.all(ex[self._diag] == 1.0):
            raise ValueError("equality rows outside the contract (dx_{k+1} with a factor other than 1)")
        rhs = np.column_stack([-ad[:, self.u_cols], b])
        sol = np.empty_like(rhs)
        _eliminate(ex, rhs, sol)
        nu = len(self.u_cols)
        tz = np.zeros((nz, self.nv))
        tz[self.u_cols, np.arange(nu)] = 1.0
        tz[self.expl_cols, nu + np.arange(len(self.expl_cols))] = 1.0
        tz[self.x_cols, :nu] = sol[:, :nu]
        t0 = np.zeros(nz)
        t0[self.x_cols] = sol[:, nu]
        # H = Tz' diag(p) Tz and f = Tz' (p t0 + c), from the blocks of Tz (identity on du and explicit slacks)
        sx = sol[:, :nu]
        px = self.p[self.x_cols]
        hess = np.zeros((self.nv, self.nv))
        hess[:nu, :nu] = sx.T @ (px[:, None] * sx)
        hess[self._vdiag] += self.p[self.var_cols]
        f = c[self.var_cols].copy()
        f[:nu] += sx.T @ (px * t0[self.x_cols] + c[self.x_cols])
        gz = qs.G.copy()  # without the soft slacks' entries (their coefficients: g_up, g_lo)
        coef = gz.data[self._soft_data]
        gz.data[self._soft_data] = 0.0
        up, lo = self.soft_rows[:, 0], self.soft_rows[:, 1]
        g_up, g_lo = coef[self._soft_first], coef[self._soft_last]
        gt = gz @ tz
        go = gz @ t0
        pair = up != lo
        if np.any(pair):  # (upper, lower) order; both rows the same affine function of the inputs
            swap = pair & (g_up > 0.0)
            up, lo = np.where(swap, lo, up), np.where(swap, up, lo)
            g_up, g_lo = np.where(swap, g_lo, g_up), np.where(swap, g_up, g_lo)
            if not (np.all(g_up[pair] < 0.0) and np.all(g_lo[pair] == -g_up[pair])
                    and np.array_equal(gt[up[pair]], gt[lo[pair]]) and np.array_equal(go[up[pair]], go[lo[pair]])
                    and np.all(hl[up[pair]] == -np.inf) and np.all(hu[lo[pair]] == np.inf)):
                raise ValueError("soft row pair outside the contract")
        single = ~pair  # one row: the slack relaxes only the side it enters with
        if not (np.all(hl[up[single & (g_up < 0.0)]] == -np.inf) and np.all(hu[up[single & (g_up > 0.0)]] == np.inf)):
            raise ValueError("soft row outside the contract")
        sc = self.soft_cols
        if not (np.all(xl[sc] == 0.0) and np.all(xu[sc] == np.inf)):
            raise ValueError("soft slack bounds outside the contract")
        gsl = np.abs(g_up)
        w = c[sc] / gsl
        rho = gsl * gsl / self.p[sc]
        # rows: the box on dx, the hard rows, the soft rows (upper bound from the upper row, lower from the lower)
        amat = np.vstack([tz[self.x_cols], gt[self.hard_rows], gt[up]])
        bu = np.concatenate([xu[self.var_cols], xu[self.x_cols] - t0[self.x_cols],
                             hu[self.hard_rows] - go[self.hard_rows], hu[up] - go[up]])
        bl = np.concatenate([xl[self.var_cols], xl[self.x_cols] - t0[self.x_cols],
                             hl[self.hard_rows] - go[self.hard_rows], hl[lo] - go[lo]])
        return hess, f, amat, bu, bl, rho, w, (tz, t0, gt[up], go[up], up, lo, gsl)

    # ------------------------------------------------------------------ solve

    def solve(self, qs, data: tuple) -> tuple[np.ndarray | None, int, str]:
        """``(z or None, iterations, message)``; raises only ValueError / RuntimeError for the caller
        (:func:`~.backends.solve_qp`) to map to a failure."""
        hess, f, amat, bu, bl, rho, w, (tz, t0, g_soft, o_soft, up, lo, gsl) = self.condense(qs, data)
        n_all = len(bu)
        rho_all = np.full(n_all, 1e-6)
        w_all = np.zeros(n_all)
        rho_all[n_all - len(rho):] = rho
        w_all[n_all - len(w):] = w
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
        self.model.soft_weights(rho_l=rho_all, rho_u=rho_all, w_l=w_all, w_u=w_all)
        v, _, flag, info = self.model.solve()
        iters = int(info["iterations"])
        if flag not in _OK:
            return None, iters, f"daqp exit flag {flag}"
        v = np.asarray(v, dtype=float)
        if not np.all(np.isfinite(v)):
            return None, iters, f"daqp returned non-finite values (exit flag {flag})"
        z = tz @ v + t0
        # soft slacks: the violation of their row (the sparse QP's optimal slack), in sigma~ units
        _, _, hl, hu, _, _ = data
        r = g_soft @ v + o_soft
        z[self.soft_cols] = np.maximum(np.maximum(r - hu[up], hl[lo] - r), 0.0) / gsl
        return z, iters, "solved"
