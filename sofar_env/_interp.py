"""Linear interpolation for the per-step hot paths.

``interp`` is numpy's compiled kernel behind :func:`numpy.interp`, without the Python
wrapper's argument handling (same kernel, same results, 0.6-0.8 us less per call).

Only the passing-side planner uses it (:mod:`sofar_env.planning.miqp`, 1.4 calls per env
step): it saves about 0.1 % of an env step there (cProfile call counts over 1,000 steps of
the ``eval/bench_env.py`` scenario, timeit per call, 1.55 ms per step), below the 2 % for
which a hand-optimised copy is kept; the track and the stack call :func:`numpy.interp`.
"""

from __future__ import annotations

import numpy as np

try:
    from numpy._core.multiarray import interp
except ImportError:  # pragma: no cover - other numpy layouts
    interp = np.interp

__all__ = ["interp"]
