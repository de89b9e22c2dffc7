"""Shared helpers of the examples: the step budget (``SOFAR_EXAMPLE_STEPS``) and a short race."""

from __future__ import annotations

import os


def max_steps(default: int) -> int:
    """Steps an example may take: ``SOFAR_EXAMPLE_STEPS`` when set (the smoke tests set it), else ``default``."""
    return int(os.environ.get("SOFAR_EXAMPLE_STEPS", default))


def race_seconds(default: float) -> float:
    """Race duration [s]: 3 s under the smoke tests, else ``default``."""
    return 3.0 if "SOFAR_EXAMPLE_STEPS" in os.environ else default
