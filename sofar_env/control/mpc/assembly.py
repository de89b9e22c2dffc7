"""The QP data of one SQP iteration, in one compiled call.

:func:`assemble` writes every vector and the values of both matrices of the QP of
:class:`~.layout.QPStructure` from the linearisation (:class:`~.linearisation.StageLinearisation`)
at the point ``(xbar, ubar)``, and tells whether the data are usable:

- cost ``c = w7 (x7 - ref)`` on the blocks ``(du_k, dx_{k+1})`` (``x7 = (ubar_k, xbar_{k+1})``; the
  reference is ``n_ref`` and ``v_ref``, 0 elsewhere), the slack weights being constant;
- dynamics ``b = f(xbar_k, ubar_k) - xbar_{k+1}`` and the values of ``A``, gathered from the flat
  linearisation buffer (``flat[a_src] a_fac``);
- inequality values of ``G`` (``flat[g_src + 3 act[slot]] (g_fac + (1 - gamma) g_gam)``) and bounds:
  lateral acceleration ``+-lat_acc_max - alat``, track ``n`` (``trk_lo``, ``trk_hi``), DCBF
  ``h_{k+1} - (1 - gamma) h_k`` of the active slots;
- the variable box ``box - x7``, each bound dropped (infinite) beyond ``box_dist`` when that is given.

Status: 0 usable; 1 some value is not finite (b, c, the matrix values, the lateral acceleration
of any stage or the barrier values of the active slots); 2 a lower variable bound exceeds its
upper one. Each value is computed with the same operations in the same order as the numpy
expressions above, so the QP is the same to the bit.
"""

from __future__ import annotations

import numpy as np

from ..._jit import kernel, maximum, minimum

__all__ = ["assemble", "all_finite", "track_rows", "STATUS_OK", "STATUS_NONFINITE", "STATUS_INCONSISTENT"]

STATUS_OK = 0
STATUS_NONFINITE = 1
STATUS_INCONSISTENT = 2


@kernel
def _finite(x):
    return x - x == 0.0  # false for nan and +-inf


@kernel
def assemble(point, refs, w7, box, lin, a_map, g_map, barrier, rows, buffers, box_out):
    """Fill the QP buffers (module docstring); returns the status. The inputs, one bundle per concept:

    * ``point``: ``(xbar (N+1, 5), ubar (N, 2))``; ``refs``: ``(n_ref, v_ref)`` (N,) (stages 1..N); ``w7`` (7,);
    * ``box``: ``(box_lo, box_hi, use_dist, box_dist)`` (the arrays (7,));
    * ``lin``: the linearisation ``(flat, f (N+1, 5), alat (N+1,), h (N+1, slots))``;
    * ``a_map``: ``(a_src, a_fac, a_out)``, the values of ``A`` from ``flat``; ``g_map``: ``(g_src, g_slot,
      g_gam, g_fac, g_out)``, those of ``G``; ``barrier``: ``(act (m,) slots, gamma)``;
    * ``rows``: ``(lat, row_lat, lat_acc_max, trk, row_trk, trk_lo, trk_hi, row_cbf)``, the rows that the QP
      has and where, the track rows' bounds (N,);
    * ``buffers``: ``(c_buf, b_buf, hl_buf, hu_buf, xl_buf, xu_buf)``, (N, nb), (N, 5), (N, nr) as in
      :class:`~.layout.QPStructure`; ``box_out``: ``(lo_out, hi_out)`` (N, 7) receive the full box on the blocks.
    """
    xbar, ubar = point
    n_ref, v_ref = refs
    box_lo, box_hi, use_dist, box_dist = box
    flat, f, alat, h = lin
    a_src, a_fac, a_out = a_map
    g_src, g_slot, g_gam, g_fac, g_out = g_map
    act, gamma = barrier
    lat, row_lat, lat_acc_max, trk, row_trk, trk_lo, trk_hi, row_cbf = rows
    c_buf, b_buf, hl_buf, hu_buf, xl_buf, xu_buf = buffers
    lo_out, hi_out = box_out
    n = ubar.shape[0]
    m = act.shape[0]
    omg = 1.0 - gamma
    ok = True
    for j in range(a_src.shape[0]):
        v = flat[a_src[j]] * a_fac[j]
        a_out[j] = v
        ok = ok and _finite(v)
    for j in range(g_src.shape[0]):
        s = g_slot[j]
        off = 3 * act[s] if s < m else 0
        v = flat[g_src[j] + off] * (g_fac[j] + omg * g_gam[j])
        g_out[j] = v
        ok = ok and _finite(v)
    for k in range(alat.shape[0]):
        ok = ok and _finite(alat[k])
    for k in range(n):
        for i in range(7):
            x = ubar[k, i] if i < 2 else xbar[k + 1, i - 2]
            if i == 3:
                r = x - n_ref[k]
            elif i == 5:
                r = x - v_ref[k]
            else:
                r = x - 0.0
            c = w7[i] * r
            c_buf[k, i] = c
            ok = ok and _finite(c)
            lo = box_lo[i] - x
            hi = box_hi[i] - x
            lo_out[k, i] = lo
            hi_out[k, i] = hi
            if use_dist:
                if lo < -box_dist[i]:
                    lo = -np.inf
                if hi > box_dist[i]:
                    hi = np.inf
            xl_buf[k, i] = lo
            xu_buf[k, i] = hi
        for i in range(5):
            b = f[k, i] - xbar[k + 1, i]
            b_buf[k, i] = b
            ok = ok and _finite(b)
        for i in range(7, c_buf.shape[1]):
            ok = ok and _finite(c_buf[k, i])
        if lat:
            hu_buf[k, row_lat] = lat_acc_max - alat[k + 1]
            hl_buf[k, row_lat + 1] = -lat_acc_max - alat[k + 1]
        if trk:
            hu_buf[k, row_trk] = trk_hi[k]
            hl_buf[k, row_trk + 1] = trk_lo[k]
        for s in range(m):
            h0 = h[k, act[s]]
            h1 = h[k + 1, act[s]]
            ok = ok and _finite(h0) and _finite(h1)
            hu_buf[k, row_cbf + s] = h1 - omg * h0
    if not ok:
        return STATUS_NONFINITE
    for k in range(n):
        for i in range(xl_buf.shape[1]):
            if xl_buf[k, i] > xu_buf[k, i]:
                return STATUS_INCONSISTENT
    return STATUS_OK


@kernel
def violated_rows(zz, check_lat, dalat, alat, lat_acc_max, check_trk, trk_lo, trk_hi, box_lo, box_hi,
                  check_box, tol, box_out):
    """Which left-out constraints the QP solution violates by more than ``tol``.

    ``zz`` (N, nb): the solution per block ``(du_k, dx_{k+1}, slacks)``. With ``check_lat``: the
    linearised lateral acceleration ``|dalat_{k+1} . (dv, ddelta) + alat_{k+1}|`` above ``lat_acc_max``;
    with ``check_trk``: ``dn_{k+1}`` outside ``[trk_lo, trk_hi]``; with ``check_box``: per column of the box
    on ``(du_k, dx_{k+1})``, a step outside ``[box_lo, box_hi]`` (``box_out`` receives the mask of the
    violated columns). Returns ``(lat, trk, box)``, ``box`` whether any column is violated.
    """
    n = zz.shape[0]
    lat = trk = box = False
    if check_lat:
        for k in range(n):
            a = abs(dalat[k + 1, 0] * zz[k, 5] + dalat[k + 1, 1] * zz[k, 6] + alat[k + 1])
            lat = lat or a > lat_acc_max + tol
    if check_trk:
        for k in range(n):
            trk = trk or zz[k, 3] - trk_hi[k] > tol or trk_lo[k] - zz[k, 3] > tol
    if check_box:
        for i in range(box_out.shape[0]):
            worst = False
            for k in range(n):
                worst = worst or box_lo[k, i] - zz[k, i] > tol or zz[k, i] - box_hi[k, i] > tol
            box_out[i] = worst
            box = box or worst
    return lat, trk, box


@kernel
def track_rows(arrays, margin, xbar, alat, lat_limit, trk_margin, trk_lo, trk_hi):
    """Bounds on ``dn_{k+1}`` of the track rows and which rows a QP at ``xbar`` starts with.

    Writes ``trk_lo = (n_min + margin) - nbar`` and ``trk_hi = (n_max - margin) - nbar`` (N,) for
    stages 1..N (``arrays``: the (5, N+1) stage rows, ``xbar`` (N+1, 5)); returns ``(lat, trk)``:
    ``max |alat_{1..N}| > lat_limit`` and ``min trk_hi < trk_margin or max trk_lo > -trk_margin``,
    with numpy's nan rules of ``max``/``min`` (what :meth:`~.rti.MPCDCBF._rows_needed` computed as
    numpy expressions).
    """
    n = trk_lo.shape[0]
    amax = abs(alat[1])
    lo_max = -np.inf
    hi_min = np.inf
    for k in range(n):
        nb = xbar[k + 1, 1]
        lo = (arrays[3, k + 1] + margin) - nb
        hi = (arrays[4, k + 1] - margin) - nb
        trk_lo[k] = lo
        trk_hi[k] = hi
        lo_max = lo if k == 0 else maximum(lo_max, lo)
        hi_min = hi if k == 0 else minimum(hi_min, hi)
        if k > 0:
            amax = maximum(amax, abs(alat[k + 1]))
    return amax > lat_limit, hi_min < trk_margin or lo_max > -trk_margin


@kernel
def all_finite(a):
    """``np.isfinite(a).all()`` of a float array of any shape."""
    for v in a.flat:
        if not _finite(v):
            return False
    return True
