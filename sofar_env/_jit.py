"""Compilation of the per-step kernels: one numba setting for the whole package.

The per-step hot paths (the passing-side planner's clearance table, ...) are loops over
small arrays; as numpy expressions their cost is the number of numpy calls (about 1 us
each), not the arithmetic. :func:`kernel` compiles such a loop once with numba:

- ``cache=True``: the machine code is stored next to the module (``__pycache__``) on the
  first call and loaded by every later process (the first call of a fresh install
  compiles, a few seconds per kernel; later ones take milliseconds);
- ``error_model="numpy"``: a float division by zero gives inf or nan as in numpy, instead of
  raising;
- no ``fastmath``: every operation is IEEE-754 in the order written, so a kernel that
  evaluates the same formulas in the same order as numpy gives the same bits (each kernel's
  tests compare it with the plain numpy form bit for bit).

Kernels written for this must avoid what differs between numpy and a loop: sums of
more than two terms (numpy sums pairwise), matrix products (BLAS) and transcendental
functions of arrays (numpy's SIMD versions); max, min, sqrt and the four operations are exact.

A kernel with many inputs takes them in bundles, one tuple per concept (the field's state, the edge band, the
QP's buffers, ...), unpacked in its first lines and documented in its docstring, so that adding a row or a
behaviour changes one bundle rather than two long argument lists; tuples of arrays and scalars cost numba
nothing at run time and change no bits.

The first kernel a process compiles (rather than loads from the cache) logs one INFO line
(logger ``sofar_env.compile``), so that the long first step of a fresh install is explained;
``python -m sofar_env.compile`` (:func:`sofar_env.compile.warm_up`) compiles ahead of time.
"""

from __future__ import annotations

import logging

import numba
from numba.core import event as _event

__all__ = ["kernel", "maximum", "minimum", "py_max", "py_min", "COMPILE_NOTICE"]

COMPILE_NOTICE = ("compiling the per-step kernels with numba and caching them on disk: once after installing, "
                  "tens of seconds per world on the first step (python -m sofar_env.compile does it ahead of time)")
"""The one INFO line of the first kernel compiled in a process."""


class _CompileNotice(_event.Listener):
    """Logs :data:`COMPILE_NOTICE` when numba starts compiling the first kernel of this package (a kernel
    loaded from the cache fires no event)."""

    def __init__(self) -> None:
        self.said = False

    def on_start(self, event) -> None:
        if self.said:
            return
        fn = getattr(event.data.get("dispatcher"), "py_func", None)
        if str(getattr(fn, "__module__", "")).partition(".")[0] == "sofar_env":
            self.said = True
            logging.getLogger("sofar_env.compile").info(COMPILE_NOTICE)

    def on_end(self, event) -> None:
        pass


_NOTICE = _CompileNotice()
_event.register("numba:compile", _NOTICE)


def kernel(fn):
    """``fn`` compiled with the package's numba setting (module docstring)."""
    return numba.njit(cache=True, error_model="numpy", fastmath=False, nogil=True)(fn)


@kernel
def maximum(a, b):
    """``np.maximum`` of two floats inside a kernel (a nan propagates; ``acc = maximum(acc, x)`` is
    ``np.max``'s reduction). One difference: for two zeros of opposite sign this returns ``a``, numpy ``b``
    (the value compares equal; only its sign bit differs)."""
    return a if (a >= b or a != a) else b


@kernel
def minimum(a, b):
    """``np.minimum`` of two floats inside a kernel (a nan propagates; for two zeros of opposite sign this
    returns ``a``, numpy ``b``, as in :func:`maximum`)."""
    return a if (a <= b or a != a) else b


@kernel
def py_max(a, b):
    """Python's ``max(a, b)`` of two floats inside a kernel: ``a`` unless ``b > a`` (a nan ``b`` is never
    taken; for two zeros, ``a``)."""
    return max(a, b)


@kernel
def py_min(a, b):
    """Python's ``min(a, b)`` of two floats inside a kernel: ``a`` unless ``b < a``."""
    return min(a, b)
