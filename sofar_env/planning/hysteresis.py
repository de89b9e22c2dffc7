"""Hysteresis of the passing-side decision: the side each opponent was given in the previous call.

The planner is called every few control steps with the opponents in any row order
(cars are filtered, reordered and respawned between calls), so the previous
decision is carried over by matching cars, not rows: each current opponent inherits
the side of the nearest opponent of the previous call, once that one is propagated
at its speed over the elapsed time, if it lies within ``cluster_gap`` along and
``safe_lat`` across the track.
"""

from __future__ import annotations

import numpy as np

from .._jit import kernel, py_max
from .config import MIQPConfig

__all__ = ["match_previous_sides", "prior_sides"]

_PRIOR_SIDE = np.array([0, -1, 1])  # sides of PlanResult for a previous side -1 (unknown), 0 (right), 1 (left)


def match_previous_sides(config: MIQPConfig, s_nodes: np.ndarray, progress: float, opp_rel: np.ndarray,
                         prev_opp: np.ndarray | None, prev_sides: np.ndarray | None) -> np.ndarray:
    """Previous side per relevant opponent: 1 left, 0 right, -1 unknown.

    Args:
        s_nodes: (nodes,) node arc lengths of the current call, relative to the ego [m].
        progress: metres the ego advanced since the previous call [m].
        opp_rel: (R, 3) relevant opponents of the current call, rows ``(s_rel, n, v)``.
        prev_opp: (Mp, 3) opponents of the previous call (None: no previous call).
        prev_sides: (Mp,) their sides, +1 left, -1 right, 0 none.

    Each current opponent inherits the side of the nearest opponent of the
    previous call (among those with a side), after propagating that one by the
    elapsed time estimated from ``progress`` and the ego speed, provided it lies
    within ``cluster_gap`` longitudinally and ``safe_lat`` laterally. Row order
    may therefore change between calls, and a respawned car (far away) does not
    inherit a stale decision.
    """
    if prev_sides is None or prev_opp is None:
        return np.full(opp_rel.shape[0], -1)
    return _match(np.asarray(s_nodes, dtype=float), float(progress), np.asarray(opp_rel, dtype=float),
                  np.asarray(prev_opp, dtype=float), np.asarray(prev_sides, dtype=np.int64), float(config.node_dt),
                  float(config.cluster_gap), float(config.safe_lat))


@kernel
def _match(s_nodes, progress, opp_rel, prev_opp, prev_sides, node_dt, gap_scale, safe_lat):
    """:func:`match_previous_sides` in one compiled call (:mod:`sofar_env._jit`), the arithmetic of its Python
    form element by element (Python's ``max`` for the lateral scale)."""
    out = np.full(opp_rel.shape[0], -1, dtype=np.int64)
    n_prev = 0
    for j in range(prev_sides.shape[0]):
        if prev_sides[j] != 0:
            n_prev += 1
    if n_prev == 0:
        return out
    v_ego = (s_nodes[1] - s_nodes[0]) / node_dt
    dt = progress / v_ego if v_ego > 0.1 and progress > 0.0 else 0.0
    if not gap_scale > 0.0:  # no longitudinal match possible (x / 0 is inf or nan)
        return out
    lat_scale = py_max(safe_lat, 1e-9)
    for r in range(opp_rel.shape[0]):
        s_r, n_r = opp_rel[r, 0], opp_rel[r, 1]
        best, best_j = np.inf, -1
        for j in range(prev_sides.shape[0]):
            if prev_sides[j] == 0:  # only the opponents that had a side
                continue
            s_pred = prev_opp[j, 0] + prev_opp[j, 2] * dt - progress
            ds = abs(s_r - s_pred) / gap_scale
            dn = abs(n_r - prev_opp[j, 1]) / lat_scale
            if ds < 1.0 and dn < 1.0 and ds + dn < best:
                best, best_j = ds + dn, j
        if best_j >= 0:
            out[r] = 1 if prev_sides[best_j] > 0 else 0
    return out


def prior_sides(relevant: np.ndarray, b_prev: np.ndarray, M: int) -> np.ndarray:
    """(M,) sides in :class:`~sofar_env.planning.miqp.PlanResult` form (+1 left, -1 right, 0 unknown
    or not relevant) from the previous sides ``b_prev`` of the ``relevant`` opponents."""
    sides = np.zeros(M, dtype=int)
    sides[relevant] = _PRIOR_SIDE[b_prev + 1]  # b_prev 1 -> 1 (left), 0 -> -1 (right), -1 -> 0 (unknown)
    return sides
