"""Layout of the RTI's QP: variables, constraint rows, fixed sparsity, and where each entry comes from.

The QP of one SQP iteration is in the steps ``(du_k, dx_{k+1})`` from the linearisation
point and the slacks. Its matrices have a fixed sparsity pattern per number of opponent
slots with rows and per presence of the lateral-acceleration and track rows
(:class:`QPStructure`); their values are gathered, with one ``take`` each, from the flat
buffer into which the linearisation is evaluated (:class:`LinearisationLayout`), so
nothing is converted or re-allocated per iteration and the QP solver can be refreshed
with ``update()`` instead of being set up again.

Slack variables enter the QP scaled by ``sqrt(Z)`` (``sigma~ = sigma sqrt(Z)``): the
Hessian entry is then 1 instead of 9e4 next to ``R = 0.01``, which made the first control
100x more accurate at equal solver tolerance.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sp

from .ends import EndOffsets
from .model import slack_weights, tracking_weights
from .types import MPCConfig

__all__ = ["N_FIXED", "LinearisationLayout", "QPStructure"]

N_FIXED = 7
"""Variables of a stage block besides the slacks: du_k (2) + dx_{k+1} (5)."""


@dataclass(frozen=True)
class LinearisationLayout:
    """Offsets in the flat buffer holding constants and the linearisation outputs A, B, dalat, dh
    of all stages (in this order, stage-major); the constants are the factors the QP entries
    that do not come from the linearisation are gathered from."""

    slots: int
    """Opponent slots of the stage function [-]."""
    nnz_a: int
    """Structural non-zeros of A = df/dx per stage [-]."""
    nnz_b: int
    """Structural non-zeros of B = df/du per stage [-]."""
    stages: int
    """N + 1 [-]."""
    lat_scale: float
    """1 / sqrt(Z) of the lateral-acceleration slack."""
    trk_scale: float
    """1 / sqrt(Z) of the track slack."""
    cbf_scale: float
    """1 / sqrt(Z) of the DCBF slack."""

    one: int = 0
    lat_neg: int = 1
    lat_pos: int = 2
    trk_neg: int = 3
    trk_pos: int = 4
    cbf_neg: int = 5
    n_const: int = 6

    @property
    def off_a(self) -> int:
        return self.n_const

    @property
    def off_b(self) -> int:
        return self.off_a + self.stages * self.nnz_a

    @property
    def off_dal(self) -> int:
        return self.off_b + self.stages * self.nnz_b

    @property
    def off_dh(self) -> int:
        return self.off_dal + self.stages * 2

    @property
    def size(self) -> int:
        return self.off_dh + self.stages * self.slots * 3

    def constants(self) -> np.ndarray:
        return np.array([1.0, -self.lat_scale, self.lat_scale, -self.trk_scale, self.trk_scale, -self.cbf_scale])


class QPStructure:
    """Fixed sparsity of the RTI QP with ``m`` opponent slots with rows, its buffers and its solver.

    Variables, stage-major: block k (k = 0..N-1) = [du_k (2), dx_{k+1} (5),
    sigma_lat_{k+1} (if ``lat``), sigma_trk_{k+1} (if ``trk``), sigma_buf_{k+1} (with end rows and
    ``MPCConfig.track_buffer``: a second slack of the four end rows, bounded by the buffer's width and cheaper
    than the track slack), sigma_cbf_{k,0..m-1}].
    Equality rows: ``dx_{k+1} - A_k dx_k - B_k du_k = f_k - xbar_{k+1}``.
    Rows of G, stage-major: [lat up, lat low] (if ``lat``), [trk up, trk low] (if ``trk``),
    cbf_0..m-1. A structure without the lateral-acceleration (or track) rows is used only
    when its solution is verified to satisfy them (``MPCDCBF._rows_needed``).

    With ``end_offsets`` (``MPCConfig.track_rows`` other than ``"reference"``) the track rows bound both
    ends of the car, ``n + g_r(e)`` linearised at ``ebar`` (:class:`~.ends.EndOffsets`): [front up, front
    low, rear up, rear low], each ``dn + g_r'(ebar) de`` with the stage's one track slack. The ``de``
    entries depend on the iterate: :meth:`fill_ends` writes them and the four bounds after the assembly.
    """

    def __init__(self, cfg: MPCConfig, m: int, lat: bool, trk: bool, a_sp: tuple, b_sp: tuple,
                 layout: LinearisationLayout, end_offsets: EndOffsets | None = None):
        n_h = cfg.horizon
        self.m = m
        self.lat = lat
        self.trk = trk
        self.end_offsets = end_offsets
        ends = trk and end_offsets is not None
        self.ends = ends
        buf = ends and cfg.track_buffer > 0.0
        self.buf = buf
        col = N_FIXED
        self.col_lat = col
        col += int(lat)
        self.col_trk = col
        col += int(trk)
        self.col_buf = col
        col += int(buf)
        self.col_cbf = col
        self.nb = nb = col + m
        self.nz = n_h * nb
        row = 0
        self.row_lat = row
        row += 2 * int(lat)
        self.row_trk = row
        row += (4 if ends else 2) * int(trk)
        self.row_cbf = row
        self.nr = nr = row + m
        iu = np.arange(n_h) * nb  # column of du_k
        ix = iu + 2  # column of dx_{k+1}

        # ---- equality: dx_{k+1} - A_k dx_k - B_k du_k = f_k - xbar_{k+1}
        a_rows, a_cols = a_sp
        b_rows, b_cols = b_sp
        rows, cols = [], []
        rows.append(np.repeat(5 * np.arange(n_h), 5) + np.tile(np.arange(5), n_h))
        cols.append(np.repeat(ix, 5) + np.tile(np.arange(5), n_h))
        kk = np.arange(1, n_h)
        rows.append((5 * kk)[:, None] + a_rows[None, :])
        cols.append(ix[kk - 1][:, None] + a_cols[None, :])
        kk = np.arange(n_h)
        rows.append((5 * kk)[:, None] + b_rows[None, :])
        cols.append(iu[:, None] + b_cols[None, :])
        eq_rows = np.concatenate([r.ravel() for r in rows])
        eq_cols = np.concatenate([c.ravel() for c in cols])
        self.n_eq = 5 * n_h

        # ---- inequalities and where each entry comes from: an index into the flat linearisation
        # buffer (see LinearisationLayout), a constant factor, and for DCBF entries the slot and a
        # (1 - gamma) flag.
        lay = layout
        kk1 = np.arange(1, n_h)
        kk = np.arange(n_h)
        base = np.arange(n_h) * nr
        rows, cols, src = [], [], []
        if lat:  # lateral acceleration (v, delta of x_{k+1}) and its slack
            dal = (lay.off_dal + (kk + 1)[:, None] * 2 + np.arange(2)[None, :]).ravel()
            for r_off, sgn in ((0, lay.lat_neg), (1, lay.lat_pos)):
                rows.append(np.repeat(base + self.row_lat + r_off, 2))
                cols.append((ix[:, None] + np.array([3, 4])[None, :]).ravel())
                src.append(dal)
                rows.append(base + self.row_lat + r_off)
                cols.append(iu + self.col_lat)
                src.append(np.full(n_h, sgn))
        if trk:  # track: n of x_{k+1} (with ends: and e) and its slack
            track_rows = ((0, lay.trk_neg), (1, lay.trk_pos))
            if ends:
                track_rows += ((2, lay.trk_neg), (3, lay.trk_pos))
            for r_off, sgn in track_rows:
                rows.append(base + self.row_trk + r_off)
                cols.append(ix + 1)
                src.append(np.full(n_h, lay.one))
                rows.append(base + self.row_trk + r_off)
                cols.append(iu + self.col_trk)
                src.append(np.full(n_h, sgn))
            if ends:  # the e entries, as placeholders (1) until fill_ends writes the slopes g_r'(ebar)
                first_end = sum(len(r) for r in rows)
                for r_off in range(4):
                    rows.append(base + self.row_trk + r_off)
                    cols.append(ix + 2)  # e of x_{k+1}
                    src.append(np.full(n_h, lay.one))
        buf_fac = []
        if buf:  # the buffer slack relaxes the four end rows as the track slack does, by its own scale
            first_buf = sum(len(r) for r in rows)
            buf_scale = 1.0 / np.sqrt(cfg.track_buffer_slack[1])
            for r_off, sgn in ((0, -1.0), (1, 1.0), (2, -1.0), (3, 1.0)):
                rows.append(base + self.row_trk + r_off)
                cols.append(iu + self.col_buf)
                src.append(np.full(n_h, lay.one))
                buf_fac.append(np.full(n_h, sgn * buf_scale))
        n_fixed = sum(len(r) for r in rows)
        slot = [np.full(n_fixed, m)]
        gam = [np.zeros(n_fixed)]
        fac = [np.ones(n_fixed)]
        if buf:
            fac[0][first_buf:first_buf + 4 * n_h] = np.concatenate(buf_fac)
        if m > 0:
            sn_v = np.array([0, 1, 3])
            # x_k part for k >= 1 (x_0 is fixed)
            r = (base[kk1][:, None, None] + self.row_cbf + np.arange(m)[None, :, None]) + 0 * sn_v[None, None, :]
            c = ix[kk1 - 1][:, None, None] + 0 * np.arange(m)[None, :, None] + sn_v[None, None, :]
            rows.append(r.ravel())
            cols.append(c.ravel())
            # x_{k+1} part
            r = (base[kk][:, None, None] + self.row_cbf + np.arange(m)[None, :, None]) + 0 * sn_v[None, None, :]
            c = ix[kk][:, None, None] + 0 * np.arange(m)[None, :, None] + sn_v[None, None, :]
            rows.append(r.ravel())
            cols.append(c.ravel())
            rows.append((base[:, None] + self.row_cbf + np.arange(m)[None, :]).ravel())
            cols.append((iu[:, None] + self.col_cbf + np.arange(m)[None, :]).ravel())
            comp = np.arange(3)[None, None, :]
            slots = np.arange(m)[None, :, None]
            base0 = lay.off_dh + kk1[:, None, None] * (lay.slots * 3) + comp + 0 * slots
            base1 = lay.off_dh + (kk + 1)[:, None, None] * (lay.slots * 3) + comp + 0 * slots
            src += [base0.ravel(), base1.ravel(), np.full(n_h * m, lay.cbf_neg)]
            slot += [(slots + 0 * kk1[:, None, None] + 0 * comp).ravel(),
                     (slots + 0 * kk[:, None, None] + 0 * comp).ravel(), np.full(n_h * m, m)]
            gam += [np.ones(base0.size), np.zeros(base1.size + n_h * m)]
            fac += [np.zeros(base0.size), -np.ones(base1.size), np.ones(n_h * m)]
        empty = np.zeros(0, dtype=np.int64)
        g_rows = np.concatenate(rows) if rows else empty
        g_cols = np.concatenate(cols) if cols else empty
        self.n_in = n_h * nr
        g_src = np.concatenate(src).astype(np.int64) if src else empty
        g_slot = np.concatenate(slot)
        g_gam = np.concatenate(gam)
        g_fac = np.concatenate(fac)

        z1, z2 = slack_weights(cfg, lat, trk, m, buf)
        self.slack_scale = 1.0 / np.sqrt(z2)
        na, nbb = len(a_rows), len(b_rows)
        eq_src = np.concatenate([np.full(5 * n_h, lay.one),
                                 (lay.off_a + kk1[:, None] * na + np.arange(na)[None, :]).ravel(),
                                 (lay.off_b + kk[:, None] * nbb + np.arange(nbb)[None, :]).ravel()])
        eq_fac = np.concatenate([np.ones(5 * n_h), -np.ones((n_h - 1) * na + n_h * nbb)])

        # ---- cost: P constant diagonal; c = w7 * (x7 - ref7) on (du_k, dx_{k+1}), slack L1 weights
        self.w7 = 2.0 * tracking_weights(cfg)
        self.P = sp.diags(np.tile(np.concatenate([self.w7, np.ones(nb - N_FIXED)]), n_h)).tocsc()
        self.c_buf = np.zeros((n_h, nb))
        self.c_buf[:, N_FIXED:] = self.slack_scale * z1
        # ---- bound buffers; entries that are never written keep their infinite / zero values
        self.hl_buf = np.full((n_h, nr), -np.inf)
        self.hu_buf = np.full((n_h, nr), np.inf)
        self.xl_buf = np.full((n_h, nb), -np.inf)
        self.xu_buf = np.full((n_h, nb), np.inf)
        self.xl_buf[:, N_FIXED:] = 0.0
        if buf:  # the scaled buffer slack sigma~ = sigma sqrt(Z) is at most the buffer's width
            self.xu_buf[:, self.col_buf] = cfg.track_buffer / self.slack_scale[self.col_buf - N_FIXED]
        self.b_buf = np.zeros((n_h, 5))

        # ---- CSC patterns; entry sources permuted to CSC data order
        self.A, perm = self._csc(eq_rows, eq_cols, self.n_eq)
        self.a_src, self.a_fac = eq_src[perm], eq_fac[perm]
        self.G, perm = self._csc(g_rows, g_cols, self.n_in)
        self.g_src, self.g_slot, self.g_gam, self.g_fac = g_src[perm], g_slot[perm], g_gam[perm], g_fac[perm]
        if ends:  # where the e entries of the end rows landed in G.data, row-major over (row, stage)
            where = np.empty(len(perm), dtype=np.int64)
            where[perm] = np.arange(len(perm))
            self.end_pos = where[first_end + np.arange(4 * n_h)]
        # rows of the DCBF constraints (for the near-activity test)
        self.cbf_rows = (np.arange(n_h)[:, None] * nr + self.row_cbf + np.arange(m)[None, :]).ravel()
        self.backend = cfg.qp_solver
        self.solver: Any = None
        """The backend's solver instance, set up on first use (see :mod:`.backends`); never copied or pickled."""
        self.solver_setup: tuple | None = None
        """PIQP: copies of the data its solver was set up with, (c, A values, b, G values, h_l, h_u, x_l, x_u);
        None when there is no solver. A copy of the structure (``copy.deepcopy``, pickle) has no solver: its
        next solve sets one up on these data, repeats ``solver_updates`` empty updates and then updates it to
        its own data, which leaves it in the state of the original's and gives that solve the original's
        result to the bit (PIQP keeps the set-up's scaling across updates, ``preconditioner_reuse_on_update``,
        and each update unscales and rescales the stored cost matrix, whose rounding depends on how many
        updates there were). OSQP's solver is not carried: a copy sets it up afresh (not bit-identical)."""
        self.solver_updates = 0
        """PIQP: the updates of its solver since its set-up."""
        self.osqp_mat: Any = None
        self.fallback: Any = None
        """The condensed DAQP model of ``MPCConfig.qp_fallback``, set up on the first QP the backend fails on;
        never copied or pickled (a copy sets it up afresh)."""

    def drop_solver(self) -> None:
        """Forget the solver: the next solve sets one up afresh on its own data."""
        self.solver = None
        self.solver_setup = None
        self.solver_updates = 0

    def __getstate__(self) -> dict:
        """Everything but the solver (a C handle; see ``solver_setup``)."""
        state = self.__dict__.copy()
        state["solver"] = state["fallback"] = None
        if self.backend != "piqp":
            state["solver_setup"] = state["osqp_mat"] = None
        return state

    def data(self) -> tuple:
        """Flat views (c, b, h_l, h_u, x_l, x_u) of the QP vectors."""
        return (self.c_buf.reshape(-1), self.b_buf.reshape(-1), self.hl_buf.reshape(-1), self.hu_buf.reshape(-1),
                self.xl_buf.reshape(-1), self.xu_buf.reshape(-1))

    def fill_matrices(self, flat: np.ndarray, act: np.ndarray, gamma: float) -> None:
        """Write the values of A and G (CSC data, fixed pattern) from the flat linearisation buffer.

        ``act``: the stage-function slot of each of the ``m`` QP slots; ``gamma``: the DCBF decay.
        Gathering into the fixed pattern takes ~10 us; building the two matrices from triplets
        instead would take ~180 us per QP (measured) and force a new solver set-up each time.
        """
        self.A.data[:] = flat[self.a_src] * self.a_fac
        slot_offset = np.zeros(self.m + 1, dtype=np.int64)  # entries of slot m are not DCBF entries
        slot_offset[: self.m] = 3 * act
        self.G.data[:] = flat[self.g_src + slot_offset[self.g_slot]] * (self.g_fac + (1.0 - gamma) * self.g_gam)

    def fill_ends(self, e_bar: np.ndarray, trk_lo: np.ndarray, trk_hi: np.ndarray,
                  kappa: np.ndarray | None = None) -> None:
        """With end rows: their ``de`` entries and their bounds, at the headings ``e_bar`` (N,) of
        x_1..x_N; ``trk_lo``/``trk_hi`` (N,) bound ``dn`` of the reference point. Row ``r`` keeps
        ``n + g_r(e)`` inside them: ``dn + g_r'(ebar) de`` within ``[trk_lo, trk_hi] - g_r(ebar)``.
        ``kappa`` (N,): the track's curvature at those stages (for ``"recoverable-curved"`` rows)."""
        values, slopes = self.end_offsets(e_bar, kappa)
        self.G.data[self.end_pos] = slopes.ravel()
        r = self.row_trk
        self.hu_buf[:, r] = trk_hi - values[0]
        self.hl_buf[:, r + 1] = trk_lo - values[1]
        self.hu_buf[:, r + 2] = trk_hi - values[2]
        self.hl_buf[:, r + 3] = trk_lo - values[3]

    def _csc(self, rows: np.ndarray, cols: np.ndarray, n_rows: int):
        order = np.lexsort((rows, cols))  # column-major
        r_sorted, c_sorted = rows[order], cols[order]
        if np.any((np.diff(c_sorted) == 0) & (np.diff(r_sorted) == 0)):
            raise RuntimeError("duplicate entries in the QP pattern")  # construction bug
        indptr = np.zeros(self.nz + 1, dtype=np.int64)
        np.add.at(indptr, c_sorted + 1, 1)
        indptr = np.cumsum(indptr)
        mat = sp.csc_matrix((np.ones(len(order)), r_sorted.astype(np.int64), indptr), shape=(n_rows, self.nz))
        return mat, order
