"""Command line: ``python -m sofar_env.tracks build|info ...``.

Examples::

    python -m sofar_env.tracks build boundaries_LS.csv --name LagunaSeca --out tracks/LagunaSeca
    python -m sofar_env.tracks build centerline.csv --format centerline --name MyTrack --out my_tracks/MyTrack
    python -m sofar_env.tracks info LagunaSeca Monza tracks/MyTrack

``build`` checks its arguments before it builds: an input that cannot be read, or an ``--out``
that is a file, cannot be created, or already holds a circuit (without ``--force``), ends it
at once with a message and exit status 2.
"""

from __future__ import annotations

import argparse
import logging
import sys

import numpy as np

from .builder import BuildConfig, build_track
from .builder.io import CircuitExistsError, OutputFolderError, check_output_folder, check_source
from .format import TrackFormatError
from .track import Track


def _parser() -> argparse.ArgumentParser:
    defaults = BuildConfig()
    parser = argparse.ArgumentParser(prog="python -m sofar_env.tracks", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)

    build = sub.add_parser("build", help="build a circuit folder from an edges or centreline CSV file")
    build.add_argument("source", help="input CSV file")
    build.add_argument("--name", required=True, help="circuit name stored in meta.json")
    build.add_argument("--out", required=True,
                       help="output folder (created if needed; one that already holds a circuit needs --force)")
    build.add_argument("--force", action="store_true",
                       help="replace the circuit files of an --out folder that already holds a circuit")
    build.add_argument("--format", choices=("edges", "centerline"), default="edges",
                       help="edges: left_x,left_y,right_x,right_y; centerline: x_m,y_m,w_tr_right_m,w_tr_left_m")
    build.add_argument("--top-speed", type=float, default=defaults.top_speed, help="speed cap [m/s]")
    build.add_argument("--clearance", type=float, default=defaults.clearance,
                       help="minimum raceline distance to each edge [m]")
    build.add_argument("--a-lat", type=float, default=defaults.a_lat_max, help="lateral acceleration limit [m/s^2]")
    build.add_argument("--a-accel", type=float, default=defaults.a_accel_max, help="acceleration limit [m/s^2]")
    build.add_argument("--a-brake", type=float, default=defaults.a_brake_max, help="braking limit [m/s^2]")
    build.add_argument("--spacing", type=float, default=defaults.spacing, help="output sample spacing [m]")
    build.add_argument("--qp-spacing", type=float, default=defaults.qp_spacing, help="QP node spacing [m]")
    build.add_argument("--qp-iterations", type=int, default=defaults.qp_iterations, help="number of QP solves")
    build.add_argument("-v", "--verbose", action="store_true", help="log the build steps")

    info = sub.add_parser("info", help="summarise circuits (names, aliases or folders)")
    info.add_argument("tracks", nargs="+")
    return parser


def _summary(track: Track) -> str:
    meta = track.meta
    return (
        f"{track.name:<14s} length {track.length:9.2f} m  samples {len(track.s):5d}  "
        f"min clearance {meta.get('min_clearance_m', float('nan')):6.3f} m  "
        f"lap time {meta.get('lap_time_s', float('nan')):7.2f} s  "
        f"max|kappa| {float(np.max(np.abs(track.kappa))):.5f} 1/m  "
        f"speed {float(track.v.min()):5.1f}-{track.max_speed:5.1f} m/s  "
        f"{meta.get('driving_direction', '?')}"
    )


def main(argv: list[str] | None = None) -> int:
    """Run the command line; returns the exit status (2 for bad input, reported on stderr)."""
    parser = _parser()
    args = parser.parse_args(argv)
    try:
        return _run(args)
    except TrackFormatError as exc:
        sys.stderr.write(f"error: {exc}\n")
        return 2
    except ValueError as exc:  # an invalid option value or an unknown circuit name
        if isinstance(exc, _UserError):
            parser.error(str(exc))  # prints usage and "error: ...", exits with status 2
        raise


class _UserError(ValueError):
    """An option value or circuit name given on the command line is invalid."""


def _check_build_arguments(args: argparse.Namespace) -> None:
    """Before anything is built (minutes for a real circuit): the input must be a readable file
    (TrackFormatError, reported as ``error: <file>: <problem>``), and ``--out`` a folder that can be
    written and, unless ``--force``, holds no circuit yet (a usage error). Both exit with status 2."""
    check_source(args.source)
    try:
        check_output_folder(args.out, overwrite=args.force)
    except CircuitExistsError as exc:
        raise _UserError(f"--out {exc}; pass --force to replace its files, or choose another --out") from None
    except OutputFolderError as exc:
        raise _UserError(f"--out {exc}") from None


def _run(args: argparse.Namespace) -> int:
    if args.command == "build":
        logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING, format="%(levelname)s %(message)s")
        config = BuildConfig(
            clearance=args.clearance,
            top_speed=args.top_speed,
            a_lat_max=args.a_lat,
            a_accel_max=args.a_accel,
            a_brake_max=args.a_brake,
            spacing=args.spacing,
            qp_spacing=args.qp_spacing,
            qp_iterations=args.qp_iterations,
        )
        try:
            config.validate()
        except ValueError as exc:
            raise _UserError(str(exc)) from None
        _check_build_arguments(args)
        track = build_track(args.source, args.name, args.out, source_format=args.format, config=config)
        sys.stdout.write(f"wrote {args.out}\n{_summary(track)}\n")
        return 0
    for name in args.tracks:
        try:
            track = Track.load(name)
        except TrackFormatError:
            raise
        except ValueError as exc:
            raise _UserError(str(exc)) from None
        sys.stdout.write(_summary(track) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
