"""Side-constraint windows of the passing-side MIQP: where, and by how much, the plan
must clear each opponent, and which opponents must be passed on the same side.

Relevance and activation. With the longitudinal gap ``g_ik = s_i(t_k) - s_nodes_k``
(opponent minus ego at node time ``t_k``), the side constraint of opponent i is
imposed at *both* end nodes of every node interval on which the linearly
interpolated gap enters ``(-safe_lon, safe_lon)``, and at every node inside it.
Since the plan is itself linear between nodes, the clearance then holds on the
whole interpolated path whenever the cars overlap, whatever the node spacing (6-12
m at 40-80 m/s, more against slow cars): no overlap can fall between nodes, without
having to inflate ``safe_lon``. An opponent with no active node is not relevant.

Braking-distance window (``closing_decel > 0``; the stack sets it). The MPC's
barrier ellipse around an opponent is ``a0 + v_close^2 / (2 a_brake)`` long, so a
plan that crosses an opponent's lane inside that distance (typically: swinging
across right in front of a much slower car after passing another one) is one the
MPC can only follow by braking hard or using barrier slack. The window then
extends by ``L_ik = v_close,ik^2 / (2 closing_decel)`` on the side where the cars
close in, with a clearance tapering like the ellipse, ``safe_lat sqrt(1 - ((|g| -
safe_lon) / L)^2)``; node intervals are covered as above (each end node keeps the
largest clearance required on the interval). Beyond the box only every
``closing_stride``-th node is kept (solve time). The side constraints then use the
per-pair clearance ``w_ik`` in place of ``safe_lat``.

Clusters. Relevant opponents closer than ``cluster_gap`` to each other at a node
where the ego overlaps either of them share one binary (connected components), so
the planner never threads between them.

Cost. The table of all opponents is one compiled call (:mod:`sofar_env._jit`) that
evaluates the formulas above in numpy's order (its tests compare it with a plain numpy
form bit for bit); the time-derivative coefficients are computed once per window.
"""

from __future__ import annotations

import numpy as np

from .._gradient import GridGradient
from .._jit import kernel, maximum, minimum
from .config import MIQPConfig

__all__ = ["ClearanceWindow", "side_clusters", "ellipse_violation"]


class ClearanceWindow:
    """The (opponent, node) clearance table of a fixed node grid (:class:`MIQPConfig`)."""

    def __init__(self, config: MIQPConfig):
        self.config = config
        self.t = np.arange(config.nodes) * config.node_dt
        """(nodes,) node times [s]."""
        self._gradient = GridGradient(self.t).coefficients()  # d/dt along the nodes (np.gradient's formula)

    def arguments(self) -> tuple:
        """The arguments of :func:`_clearance_table` after ``opp_s``: the gradient coefficients, then ``safe_lon,
        safe_lat, closing_decel, ellipse, stride`` (what :meth:`clearance` passes)."""
        cfg = self.config
        return (*self._gradient, float(cfg.safe_lon), float(cfg.safe_lat), float(cfg.closing_decel),
                cfg.window_shape == "ellipse", int(cfg.closing_stride))

    def clearance(self, s_nodes: np.ndarray, opp_s: np.ndarray) -> np.ndarray:
        """(M, N) lateral clearance [m] that node k must keep from opponent i; 0: no constraint.

        ``opp_s`` (M, N): the opponents' predicted arc lengths at the node times.

        A node gets the largest clearance required anywhere on its two adjacent node
        intervals: the plan and the gap are linear between nodes, so keeping that clearance
        at both end nodes keeps it on the whole interval.

        Rows are independent; opponents that cannot come within the (extended) window of
        the ego at any node or node interval get rows of zeros. One compiled call
        (:func:`_clearance_table`).
        """
        cfg = self.config
        N = cfg.nodes
        opp_s = np.asarray(opp_s, dtype=float)
        if opp_s.shape[0] == 0:
            return np.zeros((0, N))
        return _clearance_table(np.asarray(s_nodes, dtype=float), opp_s, *self.arguments())


@kernel
def _required(g, ext, safe_lon, safe_lat, closing, ellipse):
    """The clearance [m] required at longitudinal gap ``g`` [m] with window extension ``ext`` [m] on that side
    (module docstring): ``safe_lat`` inside the box ``|g| < safe_lon``; in the extension the elliptic taper
    ``safe_lat sqrt(1 - ((|g| - safe_lon) / ext)^2)``; with ``ellipse`` the ellipse of semi-axis
    ``safe_lon + ext`` instead; 0 beyond."""
    if ellipse:
        r = g / (safe_lon + ext) if closing else g / safe_lon
        return safe_lat * np.sqrt(maximum(1.0 - r * r, 0.0))
    over = abs(g) - safe_lon
    if over < 0.0:
        return safe_lat
    if closing and over < ext:
        r = over / ext
        return safe_lat * np.sqrt(maximum(1.0 - r * r, 0.0))
    return 0.0


@kernel
def _clearance_table(s_nodes, opp_s, uniform, two_dx, dx0, dxn, ga, gb, gc,
                     safe_lon, safe_lat, closing_decel, ellipse, stride):
    """The (M, N) table of :meth:`ClearanceWindow.clearance`, row by row (module docstring).

    Per row: the gap to the ego's nodes, the closing speed (minus its time derivative, the
    formula of :meth:`GridGradient.coefficients`), the window extension on the side the cars
    close in (``dv^2 / (2 closing_decel)``), the clearance at every node and at the point of every
    node interval nearest to a zero gap (the larger extension of its two ends), each node keeping
    the largest of its own and its two intervals'; then, with ``stride > 1``, only every
    ``stride``-th constrained node outside the box window is kept, counted outwards from the box
    (the node next to it always; rows with no box node count from their largest clearance).
    """
    M, N = opp_s.shape
    out = np.zeros((M, N))
    closing = closing_decel > 0.0
    two_decel = 2.0 * closing_decel
    gap = np.empty(N)
    ext_a = np.zeros(N)  # extension ahead of the ego (g > 0), per node
    ext_b = np.zeros(N)  # behind it
    box = np.empty(N, dtype=np.bool_)
    behind = np.empty(N, dtype=np.int64)  # distance to the last box node at or before k
    for i in range(M):
        w = out[i]
        for k in range(N):
            gap[k] = opp_s[i, k] - s_nodes[k]
        if closing:
            for k in range(N):
                if k == 0:
                    d = (gap[1] - gap[0]) / dx0
                elif k == N - 1:
                    d = (gap[N - 1] - gap[N - 2]) / dxn
                elif uniform:
                    d = (gap[k + 1] - gap[k - 1]) / two_dx
                else:
                    d = ga[k - 1] * gap[k - 1] + gb[k - 1] * gap[k] + gc[k - 1] * gap[k + 1]
                dv = -d
                e_sq = dv * dv / two_decel
                if dv > 0.0:
                    ext_a[k], ext_b[k] = e_sq, 0.0
                else:
                    ext_a[k], ext_b[k] = 0.0, e_sq
        for k in range(N):
            g = gap[k]
            box[k] = abs(g) - safe_lon < 0.0
            w[k] = _required(g, ext_a[k] if g > 0.0 else ext_b[k], safe_lon, safe_lat, closing, ellipse)
        for k in range(N - 1):
            a, b = gap[k], gap[k + 1]
            g = maximum(minimum(a, b), minimum(maximum(a, b), 0.0))  # the median of a, b and 0
            if g > 0.0:
                ext = maximum(ext_a[k], ext_a[k + 1])
            else:
                ext = maximum(ext_b[k], ext_b[k + 1])
            seg = _required(g, ext, safe_lon, safe_lat, closing, ellipse)
            w[k] = maximum(w[k], seg)
            w[k + 1] = maximum(w[k + 1], seg)
        if stride <= 1 or not closing:
            continue
        any_outside = False
        any_box = False
        for k in range(N):
            any_outside = any_outside or (w[k] > 0.0 and not box[k])
            any_box = any_box or box[k]
        if not any_outside:
            continue
        peak = 0
        if not any_box:
            for k in range(N):
                if w[k] > w[peak]:
                    peak = k
        last = -4 * N  # the last box node at or before k
        for k in range(N):
            if box[k]:
                last = k
            behind[k] = k - last
        nxt = 8 * N  # the first box node at or after k
        for k in range(N - 1, -1, -1):
            if box[k]:
                nxt = k
            if any_box:
                dist = min(behind[k], nxt - k)
            else:
                dist = abs(k - peak)
            if w[k] > 0.0 and not box[k] and dist > 1 and (dist - 1) % stride != 0:
                w[k] = 0.0
    return out


def side_clusters(pos: np.ndarray, act_rel: np.ndarray, cluster_gap: float,
                  apart: np.ndarray | None = None) -> tuple[int, np.ndarray]:
    """Connected components of the relation "must be passed on the same side".

    Two relevant opponents are linked when, at some node where the ego overlaps
    either of them (``act_rel``), they are closer than ``cluster_gap`` to each
    other along the track: the ego cannot thread between them there. (Opponents
    that only converge after the ego has passed them stay independent.) Pairs marked
    in the optional (R, R) boolean ``apart`` are never linked directly: the ego is
    already between them (two cars alongside it, one on each side).
    """
    R = pos.shape[0]
    if R == 1:
        return 1, np.zeros(1, dtype=int)
    apart = _NOT_APART if apart is None else np.asarray(apart, dtype=np.bool_)
    n, labels = _side_clusters(np.asarray(pos, dtype=float), np.asarray(act_rel, dtype=np.bool_), float(cluster_gap),
                               apart)
    return int(n), labels


_NOT_APART = np.zeros((0, 0), dtype=np.bool_)


@kernel
def _side_clusters(pos, act, gap, apart):
    """:func:`side_clusters` in one compiled call (:mod:`sofar_env._jit`): the links (``|pos_i - pos_j| < gap``
    at a node where either car is active, unless marked in ``apart``; an empty ``apart``: none marked), then
    the components labelled by the same depth-first search as the Python form (its stack in an array), so the
    labels are the same."""
    R, N = pos.shape
    linked = np.zeros((R, R), dtype=np.bool_)
    for i in range(R):
        for j in range(R):
            hit = False
            for k in range(N):
                if abs(pos[i, k] - pos[j, k]) < gap and (act[i, k] or act[j, k]):
                    hit = True
                    break
            linked[i, j] = hit and not (apart.shape[0] > 0 and apart[i, j])
    labels = np.full(R, -1, dtype=np.int64)
    stack = np.empty(R, dtype=np.int64)  # a car is pushed once: when it gets its label
    n = 0
    for i in range(R):
        if labels[i] >= 0:
            continue
        labels[i] = n
        stack[0] = i
        top = 1
        while top > 0:
            top -= 1
            j = stack[top]
            for k in range(R):
                if labels[k] < 0 and linked[j, k]:
                    labels[k] = n
                    stack[top] = k
                    top += 1
        n += 1
    return n, labels


def ellipse_violation(t: np.ndarray, s_nodes: np.ndarray, d: np.ndarray, opp_s: np.ndarray, opp_n: np.ndarray,
                      a0: float, b: float, a_brake: float, substeps: int = 8) -> np.ndarray:
    """(M,) how far [m] the lateral plan ``d`` enters each opponent's barrier ellipse, laterally (0: never).

    The ego at ``(s_nodes_k, d_k)`` and opponent i at ``(opp_s[i, k], opp_n[i])`` at the node times ``t``
    (arc lengths relative to the same origin), both linear between nodes, sampled ``substeps`` times per
    node interval. The ellipse is the MPC's barrier: lateral semi-axis ``b``, longitudinal semi-axis ``a0
    + v_close^2 / (2 a_brake)`` on the side the cars close in (``v_close`` from the nodes' gaps) and
    ``a0`` on the other. The violation at a sample is ``b sqrt(1 - (gap / a)^2) - |d - n_i|`` where
    positive, i.e. how much more lateral distance the ellipse requires there.
    """
    M, N = opp_s.shape
    if M == 0:
        return np.zeros(0)
    gap = opp_s - s_nodes[None, :]
    dv = -np.gradient(gap, t, axis=1)  # closing speed when the opponent is ahead
    tau = np.arange(substeps) / substeps
    # samples of every interval [k, k + 1) plus the last node
    def fine(x):
        x = np.atleast_2d(x)
        body = x[:, :-1, None] + (x[:, 1:, None] - x[:, :-1, None]) * tau[None, None, :]
        return np.concatenate([body.reshape(x.shape[0], -1), x[:, -1:]], axis=1)
    g, v, lat = fine(gap), fine(dv), fine(d)[0]
    closing = np.where(g > 0.0, np.maximum(v, 0.0), np.maximum(-v, 0.0))
    a = a0 + closing ** 2 / (2.0 * a_brake)
    r = g / a
    need = b * np.sqrt(np.maximum(1.0 - r * r, 0.0))
    return np.maximum(need - np.abs(lat[None, :] - np.asarray(opp_n, float)[:, None]), 0.0).max(axis=1)
