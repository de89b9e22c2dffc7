"""Circuits: the :class:`Track` (Frenet frame along the raceline) and the builder.

``Track.load("LagunaSeca")`` loads a shipped circuit; ``build_track`` (or
``python -m sofar_env.tracks build``) turns edge or centreline CSV files into a
circuit folder.
"""

from .builder import BuildConfig, build_track
from .format import TrackFormatError
from .names import TRACK_NAMES
from .track import Track

__all__ = ["Track", "TrackFormatError", "build_track", "BuildConfig", "TRACK_NAMES"]
