"""Own lines of the opponents: smooth offsets from the raceline, one fixed curve of the lap per car.

A car's line is its lateral offset plus two sinusoids in arc length,

    n(s) = offset + A (w sin(2 pi k1 s / L + p1) + (1 - w) sin(2 pi k2 s / L + p2)),

with integer wave numbers (the line closes on itself after a lap), wavelengths
``L / k`` in the configured range, ``A ~ U(0.5, 1) amplitude``, ``w ~ U(0.3, 0.7)``
and uniform phases, drawn per car and episode. ``|n(s) - offset| <= amplitude``.
The line is a target only: the car follows it with bounded lateral speed and
acceleration and inside the edges (:mod:`sofar_env.opponents.lateral`).
"""

from __future__ import annotations

import math

import numpy as np

from .._jit import kernel
from .config import LineConfig

__all__ = ["Lines", "line_at", "wave_numbers"]

_DRAWS_PER_CAR = 6
"""Random numbers drawn per car (also when lines are off, so other draws do not depend on them)."""


def wave_numbers(length: float, wavelengths: tuple[float, float]) -> np.ndarray:
    """Integer wave numbers ``k >= 1`` whose wavelengths ``length / k`` lie in ``wavelengths``.

    When none does (a lap shorter than the shortest wavelength, or a narrow range), the one
    closest to the middle of the range.
    """
    lo, hi = wavelengths
    ks = np.arange(max(1, math.ceil(length / hi)), math.floor(length / lo) + 1)
    if ks.size == 0:
        ks = np.array([max(1, round(length / (0.5 * (lo + hi))))])
    return ks


class Lines:
    """The lines of ``m`` cars on a track of length ``length`` [m]."""

    def __init__(self, offsets: np.ndarray, length: float, cfg: LineConfig, rng: np.random.Generator):
        m = offsets.shape[0]
        self.offsets = np.asarray(offsets, float).copy()
        self.length = float(length)
        u = rng.uniform(size=(m, _DRAWS_PER_CAR))
        ks = wave_numbers(self.length, cfg.wavelengths)
        k1 = ks[np.minimum((u[:, 0] * ks.size).astype(int), ks.size - 1)]
        # the second wave number differs from the first when the range allows it
        others = [ks[ks != k] if ks.size > 1 else ks for k in k1]
        k2 = np.array([o[min(int(v * o.size), o.size - 1)] for o, v in zip(others, u[:, 1])])
        amp = cfg.amplitude * (0.5 + 0.5 * u[:, 2])
        w = 0.3 + 0.4 * u[:, 3]
        self.a1, self.a2 = amp * w, amp * (1.0 - w)
        self.w1, self.w2 = 2.0 * math.pi * k1 / self.length, 2.0 * math.pi * k2 / self.length
        """Angular wave numbers [rad/m]."""
        self.p1, self.p2 = 2.0 * math.pi * u[:, 4], 2.0 * math.pi * u[:, 5]
        self.active = cfg.amplitude > 0.0

    def at(self, i: int, s: float) -> tuple[float, float]:
        """Offset of line ``i`` at ``s`` [m] and its slope dn/ds [-]."""
        if not self.active:
            return float(self.offsets[i]), 0.0
        return line_at(float(s), self.offsets[i], self.a1[i], self.a2[i], self.w1[i], self.w2[i], self.p1[i],
                       self.p2[i])


@kernel
def line_at(s, offset, a1, a2, w1, w2, p1, p2):
    """Offset and slope dn/ds of the line ``offset + a1 sin(w1 s + p1) + a2 sin(w2 s + p2)`` at ``s`` [m]
    (:meth:`Lines.at` of one car; the lateral step of the field calls it inside its kernel)."""
    x1, x2 = w1 * s + p1, w2 * s + p2
    n = offset + a1 * math.sin(x1) + a2 * math.sin(x2)
    slope = a1 * w1 * math.cos(x1) + a2 * w2 * math.cos(x2)
    return n, slope
