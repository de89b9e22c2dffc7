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

Cost. The window is evaluated for the nodes and node intervals of all opponents at
once (the arrays are small: the cost is the number of numpy calls, not the number
of opponents); the time-derivative coefficients and index tables are computed once
per window.
"""

from __future__ import annotations

import numpy as np

from .._gradient import GridGradient
from .config import MIQPConfig

__all__ = ["ClearanceWindow", "side_clusters", "ellipse_violation"]


class ClearanceWindow:
    """The (opponent, node) clearance table of a fixed node grid (:class:`MIQPConfig`)."""

    def __init__(self, config: MIQPConfig):
        self.config = config
        N = config.nodes
        self.t = np.arange(N) * config.node_dt
        """(nodes,) node times [s]."""
        self._time_gradient = GridGradient(self.t)  # d/dt along the nodes (np.gradient, precomputed)
        self._node_idx = np.arange(N)
        # _thin_extension: whether a node at distance d (in nodes) from the box window is dropped
        stride = int(config.closing_stride)
        d = np.arange(8 * N + 1)
        self._thin_drop = (d > 1) & ((d - 1) % stride != 0)

    def closing_speed(self, gap: np.ndarray) -> np.ndarray:
        """``-np.gradient(gap, self.t, axis=1)``: the closing speed when the opponent is ahead."""
        out = self._time_gradient(gap)
        np.negative(out, out=out)
        return out

    def clearance(self, s_nodes: np.ndarray, opp_s: np.ndarray) -> np.ndarray:
        """(M, N) lateral clearance [m] that node k must keep from opponent i; 0: no constraint.

        ``opp_s`` (M, N): the opponents' predicted arc lengths at the node times.

        A node gets the largest clearance required anywhere on its two adjacent node
        intervals: the plan and the gap are linear between nodes, so keeping that clearance
        at both end nodes keeps it on the whole interval.

        Rows are independent; opponents that cannot come within the (extended) window of
        the ego at any node or node interval get rows of zeros.

        (The arrays are small: the cost is the number of numpy calls, which is kept low;
        every value is computed with the same floating-point operations as the plain
        formulas in the comments.)
        """
        cfg = self.config
        N = cfg.nodes
        M = opp_s.shape[0]
        if M == 0:
            return np.zeros((0, N))
        L = cfg.safe_lon
        gap = opp_s - s_nodes[None, :]
        closing = cfg.closing_decel > 0.0
        two_decel = 2.0 * cfg.closing_decel
        # (Rows that cannot come within the window, |gap| >= L + the largest extension of the row
        # at every node and on every interval, come out as zeros; they are not filtered out first,
        # since the cost here is per numpy call, not per row.)
        if closing:
            dv = self.closing_speed(gap)
        a, b = gap[:, :-1], gap[:, 1:]
        # the point of each interval nearest to a zero gap (min(a, b) when both are positive,
        # max(a, b) when both are negative, else 0: the median of a, b and 0); nodes (first N
        # columns) and intervals (last N - 1) are evaluated together
        g_near = np.maximum(np.minimum(a, b), np.minimum(np.maximum(a, b), 0.0))
        g = np.concatenate([gap, g_near], axis=1)
        safe_lat = cfg.safe_lat
        over = np.abs(g) - L  # < 0 inside the box window |g| < L
        if closing:
            # window extension on the side the cars close in, per node: ext_a = max(dv, 0)^2 /
            # (2 closing_decel) ahead of the ego (g > 0), ext_b = max(-dv, 0)^2 / (2 closing_decel)
            # behind it, i.e. dv^2 / (2 closing_decel) where the sign of dv fits, else 0; per
            # interval the larger one of its two ends
            e_sq = dv ** 2 / two_decel
            pos_dv = dv > 0.0
            ext_a = np.where(pos_dv, e_sq, 0.0)
            ext_b = np.where(pos_dv, 0.0, e_sq)
            pos = g > 0.0
            ext = np.concatenate([np.where(pos[:, :N], ext_a, ext_b),
                                  np.where(pos[:, N:], np.maximum(ext_a[:, :-1], ext_a[:, 1:]),
                                           np.maximum(ext_b[:, :-1], ext_b[:, 1:]))], axis=1)
            # safe_lat inside the box, the elliptic taper safe_lat sqrt(1 - (over / ext)^2) in the
            # extension (0 <= over < ext; 1 - r^2 <= 1), 0 beyond
            if cfg.window_shape == "ellipse":
                out = self._ellipse(g, L + ext)
            else:
                with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
                    r = over / ext
                    cap = safe_lat * np.sqrt(np.maximum(1.0 - r * r, 0.0))
                out = np.where(over < 0.0, safe_lat, np.where(over < ext, cap, 0.0))
        elif cfg.window_shape == "ellipse":
            out = self._ellipse(g, L)
        else:
            out = np.where(over < 0.0, safe_lat, 0.0)
        w = out[:, :N]
        seg = out[:, N:]
        np.maximum(w[:, :-1], seg, out=w[:, :-1])
        np.maximum(w[:, 1:], seg, out=w[:, 1:])
        if cfg.closing_stride > 1 and closing:
            w = self._thin_extension(w, over[:, :N] < 0.0)
        return np.ascontiguousarray(w)

    def _ellipse(self, g: np.ndarray, semi: np.ndarray | float) -> np.ndarray:
        """``safe_lat sqrt(1 - (g / semi)^2)`` inside the ellipse of longitudinal semi-axis ``semi``, 0 outside."""
        r = g / semi
        return self.config.safe_lat * np.sqrt(np.maximum(1.0 - r * r, 0.0))

    def _thin_extension(self, w: np.ndarray, box: np.ndarray) -> np.ndarray:
        """Keep every ``closing_stride``-th constrained node outside the box window, counted outwards
        from it (the node next to the box is always kept). The clearance decreases away from the box,
        so each kept node requires at least what the dropped nodes beyond it would have."""
        outside = (w > 0.0) & ~box  # constrained nodes outside the box: the candidates
        if not outside.any():
            return w
        N = w.shape[1]
        k = self._node_idx
        big = 4 * N
        # distance (in nodes) to the nearest box node, from both sides
        last = np.maximum.accumulate(np.where(box, k, -big), axis=1)
        nxt = np.minimum.accumulate(np.where(box, k, 2 * big)[:, ::-1], axis=1)[:, ::-1]
        dist = np.minimum(k - last, nxt - k)
        # rows with candidates but no box node (window crossed between nodes): count from the
        # largest clearance
        empty = ~box.any(axis=1) & outside.any(axis=1)
        if empty.any():
            dist[empty] = np.abs(k[None, :] - np.argmax(w[empty], axis=1)[:, None])
        # dropped: candidates at a distance d > 1 with (d - 1) % stride != 0
        drop = outside & self._thin_drop[dist]
        if not drop.any():
            return w
        out = w.copy()
        out[drop] = 0.0
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
    close = np.abs(pos[:, None, :] - pos[None, :, :]) < cluster_gap
    either = act_rel[:, None, :] | act_rel[None, :, :]
    linked = (close & either).any(axis=2)
    if apart is not None:
        linked &= ~apart
    linked = linked.tolist()
    labels = [-1] * R
    n = 0
    for i in range(R):
        if labels[i] >= 0:
            continue
        labels[i] = n
        stack = [i]
        while stack:
            j = stack.pop()
            for k in range(R):
                if labels[k] < 0 and linked[j][k]:
                    labels[k] = n
                    stack.append(k)
        n += 1
    return n, np.asarray(labels, dtype=int)


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
