"""Table look-ups inside the stack's compiled kernels, with numpy's bits and fewer cycles.

The footprint edges, the ego's node positions and the opponents' pace prediction each
interpolate a track column at 100-400 points per call. :func:`~sofar_env._interp.locate` and
:func:`~sofar_env._interp.interp_located` give numpy's bits whatever the guess; what costs is a
binary search when the guess misses (the points are metres apart, the knots 1 m), the float
modulo (a libm ``fmod`` call), the division of the slope, and calling a kernel with array
arguments from a kernel (each array is reference-counted per call, ~25 ns). So the kernels
that use these helpers:

* wrap with :func:`wrap_mod`: ``x % length`` without ``fmod`` where it is a no-op or one exact
  subtraction (scalars only: a cheap call);
* try the interval ``int(x / h)`` of nearly evenly spaced knots (the track's columns, spacing
  ``h``) or the previous point's interval moved forward (the travel-time table) first, written
  out inline, and call ``locate`` only when that misses;
* interpolate with the table's :func:`slopes`, computed once, as ``slope[j] (x - xp[j]) + fp[j]``
  (``interp_located``'s formula), inline, and call ``interp_located`` for its special cases
  (ends, knots, nan).

All of it gives the bits of the plain forms (:mod:`sofar_env._jit`; tests in
``tests/test_fast_paths.py``).
"""

from __future__ import annotations

import numpy as np

from .._jit import kernel

__all__ = ["slopes", "wrap_mod"]


@kernel
def wrap_mod(x, length):
    """``x % length`` (Python's and numpy's floor modulo) for ``length > 0``: ``x`` itself on ``(0, length)``,
    ``x - length`` on ``[length, 2 length)`` (exact by Sterbenz's lemma, so ``fmod``'s exact result), the
    modulo elsewhere (zero, negative, far, nan)."""
    if 0.0 < x < length:
        return x
    if length <= x < 2.0 * length:
        return x - length
    return x % length


def slopes(xp: np.ndarray, fp: np.ndarray) -> np.ndarray:
    """(len - 1,) slopes ``(fp[j+1] - fp[j]) / (xp[j+1] - xp[j])`` of a table, as ``interp_located``
    computes each of them."""
    xp = np.asarray(xp, float)
    fp = np.asarray(fp, float)
    return (fp[1:] - fp[:-1]) / (xp[1:] - xp[:-1])
