"""The MPC's per-stage data at the points of its warm start, in one compiled call.

At every control step the MPC needs, at the arc lengths ``s_k`` its warm start predicts
(:meth:`~sofar_env.control.mpc.MPCDCBF.predicted_s`), the raceline's curvature, the speed
reference (``speed_factor`` times the speed profile), the lateral reference (the plan in
force, interpolated) and the track edges (:class:`~sofar_env.stack.edges.TrackEdges`,
before the heading-error tightening). :class:`StageLookup` computes four of them in one
compiled call (:mod:`sofar_env._jit`) instead of a dozen numpy calls: each value with the
formulas, tables and interpolation of the track's own accessors
(:meth:`~sofar_env.tracks.Track.curvature`, :meth:`~sofar_env.tracks.Track.speed`,
:meth:`~sofar_env.tracks.Track.width_left`, :class:`~sofar_env.stack.edges.TrackEdges`), so the
same bits. The lateral reference stays :meth:`~sofar_env.planning.miqp.PlanResult.lateral_at`
(numpy's interpolation), whose node positions may repeat (a plan that stops), which the
compiled look-up does not handle as numpy does.
"""

from __future__ import annotations

import numpy as np

from .._interp import interp_located, locate
from .._jit import kernel
from .edges import TrackEdges, _narrowest_edges

__all__ = ["StageLookup"]


class StageLookup:
    """Curvature, speed reference and edges at the points of the MPC's warm start (module docstring)."""

    def __init__(self, track, edges: TrackEdges, speed_factor: float):
        self._kappa = track.table("kappa")[1]  # every column shares the knots of the edges' tables
        self._v = track.table("v")[1]
        self._length = float(track.length)
        self._speed_factor = float(speed_factor)
        self._edges = edges.kernel_data()

    def __call__(self, ego_s: float, s_rel: np.ndarray) -> tuple[np.ndarray, ...]:
        """``(s_abs, kappa, v_ref, n_min, n_max)`` at ``s_abs = ego_s + s_rel`` [m]: the raceline's curvature
        [1/m], ``speed_factor`` times the speed profile [m/s], and the edges of
        :class:`~sofar_env.stack.edges.TrackEdges` [m]."""
        return _stage_rows(float(ego_s), np.asarray(s_rel, dtype=float), self._speed_factor, self._kappa, self._v,
                           self._length, *self._edges)


@kernel
def _stage_rows(ego_s, s_rel, speed_factor, kappa, v, length, footprint, offsets, knots, wl, wr, slope_l, slope_r,
                inv_spacing):
    """:meth:`StageLookup.__call__`: the track's columns (closed tables on ``knots``) at ``s_abs % length`` with
    numpy's interpolation (:func:`~sofar_env._interp.interp_located`), and the edges (``footprint``:
    :func:`~sofar_env.stack.edges._narrowest_edges`, else the widths ``wl``, ``wr`` there)."""
    n = s_rel.shape[0]
    s_abs = np.empty(n)
    kap = np.empty(n)
    v_ref = np.empty(n)
    n_min = np.empty(n)
    n_max = np.empty(n)
    for k in range(n):
        s = ego_s + s_rel[k]
        s_abs[k] = s
        x = s % length
        j = locate(x, knots, -1)
        kap[k] = interp_located(j, x, knots, kappa)
        v_ref[k] = speed_factor * interp_located(j, x, knots, v)
        if not footprint:
            n_min[k] = -interp_located(j, x, knots, wr)
            n_max[k] = interp_located(j, x, knots, wl)
    if footprint:
        n_min, n_max = _narrowest_edges(s_abs, offsets, knots, wl, wr, slope_l, slope_r, inv_spacing, length)
    return s_abs, kap, v_ref, n_min, n_max
