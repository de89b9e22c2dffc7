"""Argument types of the command lines: every number is checked where it enters.

Each name here is a callable for ``argparse``'s ``type=``: it turns the text of one value into
a number, or raises ``argparse.ArgumentTypeError``, which ``argparse`` reports as a usage error
(the usage line, then ``error: argument --flag: ...``, exit status 2) before the script does any
work. A count that must be positive is therefore never 0 or negative after parsing, so a script
may write ``args.episodes or 5`` for "not given" without 0 silently meaning the default.

The generated options of :mod:`sofar_agents.cli` use them too: a dataclass field annotated
``Annotated[int, positive_int]`` becomes an option of that type.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable

__all__ = ["positive_int", "nonneg_int", "int_at_least", "positive_float", "nonneg_float", "finite_float",
           "float_in", "gamma_value"]


def _int(text: str) -> int:
    try:
        return int(text)
    except (TypeError, ValueError):
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None


def _float(text: str) -> float:
    try:
        value = float(text)
    except (TypeError, ValueError):
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"expected a finite number, got {text!r}")
    return value


def int_at_least(low: int) -> Callable[[str], int]:
    """The type of a whole number ``>= low``."""

    def check(text: str) -> int:
        value = _int(text)
        if value < low:
            raise argparse.ArgumentTypeError(f"must be a whole number >= {low}, got {text!r}")
        return value

    check.__name__ = f"int_at_least_{low}"
    return check


positive_int = int_at_least(1)
"""A whole number >= 1: counts of things that must exist (episodes, workers, steps, rounds)."""
positive_int.__name__ = "positive_int"
nonneg_int = int_at_least(0)
"""A whole number >= 0: seeds, and counts where 0 means none (opponents, 0 = off)."""
nonneg_int.__name__ = "nonneg_int"


def finite_float(text: str) -> float:
    """Any finite number (not nan or inf)."""
    return _float(text)


def float_in(low: float, high: float = math.inf, *, low_open: bool = False,
             high_open: bool = False) -> Callable[[str], float]:
    """The type of a finite number in the interval from ``low`` to ``high`` (closed unless ``low_open`` /
    ``high_open``; ``high`` infinite: no upper bound)."""
    if math.isfinite(high):
        bounds = ("(" if low_open else "[") + f"{low:g}, {high:g}" + (")" if high_open else "]")
        wanted = f"must lie in {bounds}"
    else:
        bounds = (">" if low_open else ">=") + f" {low:g}"
        wanted = f"must be a number {bounds}"

    def check(text: str) -> float:
        value = _float(text)
        if value < low or (low_open and value == low) or value > high or (high_open and value == high):
            raise argparse.ArgumentTypeError(f"{wanted}, got {text!r}")
        return value

    check.__name__ = f"float_in {bounds}"
    return check


positive_float = float_in(0.0, low_open=True)
"""A finite number > 0: durations [s], rates, scales."""
positive_float.__name__ = "positive_float"
nonneg_float = float_in(0.0)
"""A finite number >= 0: pace ratios, distances, weights."""
nonneg_float.__name__ = "nonneg_float"


def gamma_value(text: str) -> float:
    """A barrier decay gamma in ``[GAMMA_MIN, GAMMA_MAX]`` of :mod:`sofar_env.constants` (a fixed gamma outside
    it would be clipped by the environment and run under another value than its name)."""
    from sofar_env.constants import GAMMA_MAX, GAMMA_MIN  # here: importing sofar_env takes a tenth of a second

    return float_in(GAMMA_MIN, GAMMA_MAX)(text)
