"""Linear interpolation for the per-step hot paths.

``interp`` is numpy's compiled kernel behind :func:`numpy.interp`, without the Python
wrapper's argument handling (same kernel, same results, 0.6-0.8 us less per call).
``interp_at`` is the same interpolation at one point, for use inside compiled kernels
(:mod:`sofar_env._jit`): numpy's formula and special cases, so numpy's bits.

Used wherever an env step interpolates arrays: the track's sampled columns at array
arguments, the opponents' pace prediction, the MPC's track edges and the passing-side
planner (about 20 calls per env step of the ``bench/bench_env.py`` scenario).
"""

from __future__ import annotations

import numpy as np

from ._jit import kernel

try:
    from numpy._core.multiarray import interp
except ImportError:  # pragma: no cover - other numpy layouts
    interp = np.interp

__all__ = ["interp", "interp_at", "interp_located", "locate", "wrap_at"]


@kernel
def locate(x, xp, guess):
    """Where ``x`` falls in the strictly increasing ``xp`` (at least 2 samples): ``j`` with ``xp[j] <= x <
    xp[j + 1]``; ``-1`` left of ``xp[0]``, ``len(xp) - 1`` from ``xp[-1]`` on, ``-2`` for a nan ``x``. A
    ``guess`` (e.g. the previous point's ``j`` for increasing points) is tried first, then its next
    interval, then a binary search: the result does not depend on it."""
    n = xp.shape[0]
    if x != x:
        return -2
    if x < xp[0]:
        return -1
    if x >= xp[n - 1]:
        return n - 1
    if 0 <= guess < n - 1 and xp[guess] <= x:
        if x < xp[guess + 1]:
            return guess
        if guess + 2 < n and x < xp[guess + 2]:
            return guess + 1
    lo, hi = 0, n - 1  # xp[lo] <= x < xp[hi]
    while hi - lo > 1:
        mid = (lo + hi) >> 1
        if xp[mid] <= x:
            lo = mid
        else:
            hi = mid
    return lo


@kernel
def interp_located(j, x, xp, fp):
    """``np.interp(x, xp, fp)`` with ``j = locate(x, xp, ...)``: numpy's arithmetic: ``fp[0]`` left of
    ``xp[0]``, ``fp[-1]`` from ``xp[-1]`` on, ``fp[j]`` at a knot, else ``slope (x - xp[j]) + fp[j]`` with
    ``slope = (fp[j+1] - fp[j]) / (xp[j+1] - xp[j])`` (and numpy's retry from the right end of the
    interval if that is nan); nan for a nan ``x``. Tables that share ``xp`` share one ``locate``."""
    n = xp.shape[0]
    if j == -2:
        return x
    if j == -1:
        return fp[0]
    if j == n - 1:
        return fp[n - 1]
    if xp[j] == x:
        return fp[j]
    slope = (fp[j + 1] - fp[j]) / (xp[j + 1] - xp[j])
    y = slope * (x - xp[j]) + fp[j]
    if y != y:
        y = slope * (x - xp[j + 1]) + fp[j + 1]
        if y != y and fp[j] == fp[j + 1]:
            y = fp[j]
    return y


@kernel
def interp_at(x, xp, fp):
    """``np.interp(x, xp, fp)`` at one float ``x`` (``xp`` strictly increasing, at least 2 samples), to
    numpy's bits (:func:`interp_located`)."""
    return interp_located(locate(x, xp, -1), x, xp, fp)


@kernel
def wrap_at(s, length):
    """``s`` wrapped into ``[0, length)`` as the track wraps it (``s % length``, numpy's and Python's
    floor modulo; 0 where rounding gives ``length``)."""
    r = s % length
    return 0.0 if r >= length else r
