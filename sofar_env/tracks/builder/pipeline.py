"""The builder's pipeline: source edges -> circuit arrays and metadata -> circuit folder.

:func:`build_from_edges` runs the stages on two closed edges (edge preparation and
centreline, minimum-curvature raceline with its clearance check, sampling of
heading, curvature and widths, speed profile) and assembles ``meta.json``;
:func:`build_track` reads an input CSV file, builds, and optionally writes the
circuit folder.
"""

from __future__ import annotations

import dataclasses
import logging
import os
import warnings
from pathlib import Path

import numpy as np

from ..format import FORMAT_VERSION, LEFT_EDGE_FILE, RACELINE_FILE, RIGHT_EDGE_FILE
from ..track import Track
from .checks import check_edges
from .config import BuildConfig
from .edges import centerline, orient_edges, prepare_edge
from .io import (
    CENTERLINE_FILE,
    BuiltCircuit,
    check_output_folder,
    read_centerline_csv,
    read_edges_csv,
    sha256,
    write_circuit,
)
from .polyline import (
    clean_closed,
    closest_points,
    edge_widths,
    polyline_distance,
    signed_area,
    spline_resample_closed,
    tangent_normal,
)
from .raceline import fit_raceline
from .speed import lap_time, speed_profile

__all__ = ["PROVENANCE", "build_from_edges", "build_track"]

logger = logging.getLogger(__name__)

PROVENANCE = (
    "Edge positions of the public raceway as published by the SOfAR paper authors "
    "(github.com/hassanjardali/SOfAR); only the edge positions were taken. Resampled "
    "edges, centreline, widths, raceline, curvature and speed profile were computed "
    "by the sofar_env.tracks builder."
)


def _round_sig(values: np.ndarray, digits: int = 12) -> np.ndarray:
    """Values rounded as the ``%.{digits}g`` format stores them."""
    return np.array([float(f"{v:.{digits}g}") for v in values])


def build_from_edges(
    left: np.ndarray,
    right: np.ndarray,
    name: str,
    config: BuildConfig | None = None,
    source: dict | None = None,
    label: str | None = None,
) -> BuiltCircuit:
    """Build a circuit from two closed edges (left = +n side in the driving direction).

    The edges are checked first (:func:`.checks.check_edges`); ``label`` names the input
    in the error messages (default: the circuit name).
    """
    config = config or BuildConfig()
    config.validate()
    label = label or f"edges of {name}"
    left = clean_closed(np.asarray(left, dtype=float), f"{label} (left edge)")
    right = clean_closed(np.asarray(right, dtype=float), f"{label} (right edge)")
    check_edges(left, right, label)
    left, right = orient_edges(left, right)
    anchor = 0.5 * (left[0] + closest_points(left[:1], right)[0])

    left_s, disp_l = prepare_edge(left, config)
    right_s, disp_r = prepare_edge(right, config)
    logger.info("edge smoothing moved points by at most %.3f m", max(disp_l, disp_r))

    center = centerline(left_s, right_s, config)
    race = fit_raceline(center, left_s, right_s, left, right, anchor, name, config)
    s, length, curve, pts = race.s, race.length, race.curve, race.check_points
    d_left, d_right = race.d_left, race.d_right
    if race.narrow.any():
        warnings.warn(
            f"{name}: corridor narrower than 2 x clearance at {int(race.narrow.sum())} QP nodes; "
            "the raceline is centred there",
            stacklevel=2,
        )

    x, y, dx, dy, ddx, ddy = curve.eval(s, order=2)
    xy = np.column_stack([x, y])
    speed2 = dx * dx + dy * dy
    psi = np.arctan2(dy, dx)
    kappa = (dx * ddy - dy * ddx) / np.power(speed2, 1.5)
    normal = np.column_stack([-dy, dx]) / np.sqrt(speed2)[:, None]
    w_left, w_right = edge_widths(xy, normal, left_s, right_s)
    # The speed profile is computed from the values exactly as they are stored
    # (s and L rounded to the micrometre, kappa to 12 digits) so that the stored
    # columns satisfy the limits to rounding error.
    length = round(float(length), 6)
    s = np.round(s, 6)
    kappa = _round_sig(kappa)
    ds = np.diff(np.append(s, length))
    v = _round_sig(speed_profile(kappa, ds, config.a_lat_max, config.a_accel_max, config.a_brake_max, config.top_speed))
    raceline = np.column_stack([s, x, y, psi, kappa, w_left, w_right, v])

    # centreline with widths, at the output spacing, starting near the anchor
    c_start = int(np.argmin(np.hypot(*(center - anchor).T)))
    c_pts, c_len = spline_resample_closed(np.roll(center, -c_start, axis=0), config.spacing)
    _, c_norm = tangent_normal(c_pts)
    c_wl, c_wr = edge_widths(c_pts, c_norm, left_s, right_s)
    c_s = np.arange(len(c_pts)) * (c_len / len(c_pts))
    centerline_table = np.column_stack([c_s, c_pts, c_wl, c_wr])

    area = signed_area(xy)
    source_clearance = min(float(polyline_distance(pts, left).min()), float(polyline_distance(pts, right).min()))
    import osqp  # imported lazily: only the builder needs it (for the version recorded below)

    meta = {
        "format_version": FORMAT_VERSION,
        "name": name,
        "length_m": length,
        "num_samples": int(len(s)),
        "driving_direction": "counter-clockwise" if area > 0 else "clockwise",
        "lap_time_s": round(lap_time(v, ds), 4),
        "min_clearance_m": round(float(min(d_left.min(), d_right.min())), 4),
        "min_clearance_left_m": round(float(d_left.min()), 4),
        "min_clearance_right_m": round(float(d_right.min()), 4),
        "min_clearance_source_edges_m": round(source_clearance, 4),
        "max_abs_kappa_radpm": round(float(np.max(np.abs(kappa))), 6),
        "speed_min_mps": round(float(v.min()), 4),
        "speed_max_mps": round(float(v.max()), 4),
        "track_width_min_m": round(float(np.min(c_wl + c_wr)), 4),
        "narrow_qp_nodes": int(race.narrow.sum()),
        "edge_smoothing_max_displacement_m": round(max(disp_l, disp_r), 4),
        "builder": {**dataclasses.asdict(config), "qp_solver": f"osqp {getattr(osqp, '__version__', '?')}"},
        "source": dict(source or {}),
        "provenance": PROVENANCE,
        "files": {
            "raceline": RACELINE_FILE,
            "left_edge": LEFT_EDGE_FILE,
            "right_edge": RIGHT_EDGE_FILE,
            "centerline": CENTERLINE_FILE,
        },
    }
    return BuiltCircuit(raceline, left_s, right_s, centerline_table, meta)


def build_track(
    source: str | os.PathLike,
    name: str,
    out_dir: str | os.PathLike | None = None,
    *,
    source_format: str = "edges",
    config: BuildConfig | None = None,
) -> Track:
    """Build a circuit from a CSV file and return it as a :class:`Track`.

    ``source_format`` is ``"edges"`` (``left_x, left_y, right_x, right_y``) or
    ``"centerline"`` (``x_m, y_m, w_tr_right_m, w_tr_left_m``).  When
    ``out_dir`` is given the circuit files are written there (replacing those of
    a circuit already there) and the returned Track is loaded back from disk; a
    ``out_dir`` that cannot be written (an existing file, a folder without write
    permission) raises :class:`~.io.OutputFolderError` before anything is built.
    """
    if out_dir is not None:
        check_output_folder(out_dir)
    path = Path(source)
    if source_format == "edges":
        left, right = read_edges_csv(path)
    elif source_format == "centerline":
        left, right = read_centerline_csv(path)
    else:
        raise ValueError(f"unknown source format {source_format!r}; use 'edges' or 'centerline'")
    info = {"file": path.name, "sha256": sha256(path), "format": source_format}
    built = build_from_edges(left, right, name, config, source=info, label=str(path))
    if out_dir is None:
        return built.to_track()
    folder = write_circuit(out_dir, built)
    return Track.load(folder)
