"""Circuit builder: track edges -> centreline -> minimum-curvature raceline -> speed profile.

Stages (all geometry in metres), one module each:

1. :mod:`.edges`: the two edges are put in the driving direction, resampled at
   uniform arc length and lightly smoothed (periodic Gaussian, moves points by
   centimetres); a centreline is found by pairing the edges and re-centring it
   along its normals.
2. :mod:`.raceline`: a minimum-curvature QP (a lateral shift ``alpha_i`` along the
   normals of a reference line, curvature linearised around the reference,
   solved with OSQP, iterated with the previous solution as the new reference),
   bounded so that the raceline keeps at least ``clearance`` metres from each
   edge; the clearance is verified with exact point-to-polyline distances and
   the bounds are tightened locally and the QP re-solved where needed.
3. :mod:`.pipeline`: the raceline is sampled at uniform arc length; heading and
   signed curvature come from the periodic cubic spline that
   :class:`~sofar_env.tracks.Track` uses, widths from ray-edge intersections
   along the normal.
4. :mod:`.speed`: a speed profile from a forward-backward pass (lateral
   acceleration limit, acceleration and braking limits, top speed) on the
   closed loop.

:mod:`.polyline` holds the closed-polyline geometry they share, :mod:`.io` the
input formats and the circuit folder, :mod:`.config` the parameters.
"""

from .config import BuildConfig
from .io import CENTERLINE_FILE, BuiltCircuit, read_centerline_csv, read_edges_csv, write_circuit
from .pipeline import build_from_edges, build_track
from .polyline import polyline_distance, ray_polyline_distance
from .speed import lap_time, speed_profile

__all__ = [
    "BuildConfig",
    "BuiltCircuit",
    "CENTERLINE_FILE",
    "build_track",
    "build_from_edges",
    "write_circuit",
    "read_edges_csv",
    "read_centerline_csv",
    "speed_profile",
    "lap_time",
    "polyline_distance",
    "ray_polyline_distance",
]
