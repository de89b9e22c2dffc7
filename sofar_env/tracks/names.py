"""The circuits shipped with the package and their case-insensitive names and aliases."""

from __future__ import annotations

from typing import Any

from ..constants import CIRCUITS

__all__ = ["TRACK_NAMES", "ALIASES", "resolve_track_name", "unknown_name_error"]

TRACK_NAMES = CIRCUITS
"""Circuits shipped with the package (folders of ``sofar_env.track_data``)."""

ALIASES = {"ls": "LagunaSeca", "ims": "Indianapolis", "ks": "Kentucky"}
ALIASES.update({name.lower(): name for name in TRACK_NAMES})


def resolve_track_name(name: str) -> str:
    """Canonical circuit name for a (case-insensitive) name or alias.

    Raises ValueError listing the valid names when ``name`` is unknown.
    """
    key = str(name).strip().lower()
    if key in ALIASES:
        return ALIASES[key]
    raise unknown_name_error(name)


def unknown_name_error(name: Any) -> ValueError:
    """The error for an unknown circuit name, listing the valid names and aliases."""
    valid = ", ".join(TRACK_NAMES) + " (aliases: LS, IMS, KS)"
    return ValueError(f"unknown track {name!r}; valid names: {valid}")
