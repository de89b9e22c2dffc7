"""Copies of the shipped circuit folders, for tests that break one file of a circuit.

Imported as ``shipped_circuits`` (this folder is on the path when pytest runs its tests).
"""

from __future__ import annotations

import shutil
from importlib import resources
from pathlib import Path

CIRCUIT_FILES = ("raceline.csv", "left_edge.csv", "right_edge.csv", "meta.json")


def copy_circuit(name: str, tmp_path: Path) -> Path:
    """Copy the files ``Track.load`` reads of the shipped circuit ``name`` into ``tmp_path/name``."""
    src = resources.files("sofar_env.track_data").joinpath(name)
    dst = tmp_path / name
    dst.mkdir()
    for fname in CIRCUIT_FILES:
        with resources.as_file(src.joinpath(fname)) as path:
            shutil.copy(path, dst / fname)
    return dst
