"""Lateral motion of an opponent: a rate- and acceleration-bounded tracker, edge bands, keep-clear bounds.

Pure math on floats and small arrays, compiled (:mod:`sofar_env._jit`) so that the lateral step of the
field (:mod:`sofar_env.opponents.steering`) combines them in one compiled call; each is also callable from
Python:

* :func:`track_target`: one step of a tracker of a target offset whose lateral speed
  and acceleration never exceed the given bounds (a braking curve near the target
  and near the bounds of the target, a first-order approach in its last few
  decimetres);
* :class:`EdgeBand`: where the reference point of a car may be across the track:
  the *soft* band keeps the footprint ``inner`` inside both edges, and its
  look-ahead envelope also leaves room to get back into the band where the track
  narrows ahead at a fraction of the lateral speed bound; the *hard* band is the
  last resort that keeps every corner on the track at the car's current heading;
* :func:`keep_clear`: bounds that stop a car from closing sideways on another one.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.ndimage import minimum_filter1d

from .._interp import interp, interp_located, locate
from .._jit import kernel, maximum, minimum, py_max, py_min
from ..tracks.curve import floor_mod, lerp_wrapped

__all__ = ["EdgeBand", "keep_clear", "track_target"]

_APPROACH_TIME = 0.5
"""Time constant of the first-order approach of the tracker in the last decimetres [s]."""

_CORNER_WINDOW = 5.0
"""The bands use the smallest width within this arc-length distance [m]: a footprint corner is at
most half a car length (2.45 m) ahead or behind the reference point."""

_HARD_SLACK = 0.05
"""Distance the hard band keeps the footprint corners inside the edges [m]."""

_LOOKAHEAD_TIME = 8.0
"""The soft envelope looks this far ahead at the car's speed (at least 50 m) [s]."""

_LOOKAHEAD = np.linspace(0.0, 1.0, 33)
"""Points of the look-ahead of the soft envelope, as fractions of its reach."""

_ROOM_SAMPLES = 400
"""Most points of :meth:`EdgeBand.room` (2 km at the 5 m spacing)."""


@kernel
def track_target(n: float, n_dot: float, target: float, target_rate: float, v_max: float, a_max: float,
                 dt: float, lo: float = -math.inf, hi: float = math.inf) -> tuple[float, float]:
    """One step of length ``dt`` of the lateral tracker: the new ``(n, n_dot)``.

    The commanded rate is ``target_rate`` plus a correction toward ``target`` along the braking
    curve ``sqrt(a_max |e|)`` (half the deceleration bound, so the discrete tracker does not
    overshoot) or ``|e| / 0.5 s`` near it, clipped to ``+-v_max`` and to the braking curves of the
    bounds ``lo <= target <= hi`` (so that a target moving toward a bound does not carry the car
    past it); the rate then moves toward it by at most ``a_max dt``. Hence
    ``|n_dot_new| <= max(|n_dot|, v_max)`` and ``|n_dot_new - n_dot| <= a_max dt``; ``n``
    integrates the rate with the trapezoidal rule.
    """
    e = target - n
    mag = py_min(math.sqrt(a_max * abs(e)), abs(e) / _APPROACH_TIME)
    r = target_rate + math.copysign(mag, e)
    up = py_min(v_max, _stopping_rate(hi - n, a_max))
    down = py_min(v_max, _stopping_rate(n - lo, a_max))
    r = py_min(py_max(r, -down), up)
    step = a_max * dt
    n_dot_new = n_dot + py_min(py_max(r - n_dot, -step), step)
    return n + 0.5 * (n_dot + n_dot_new) * dt, n_dot_new


@kernel
def _stopping_rate(room, a_max):
    """Largest rate toward a bound ``room`` [m] away that still stops in time (0 at or past it)."""
    if room <= 0.0:
        return 0.0
    return py_min(math.sqrt(a_max * room), room / _APPROACH_TIME) if room < math.inf else math.inf


def keep_clear(n: float, n_other: float, separation: float, share: float = 1.0,
               left: bool | None = None) -> tuple[float, float]:
    """Bounds ``(lo, hi)`` on a car's offset that keep it from closing sideways on another car.

    The car stays on its side of ``n_other`` (``left``: ``n >= n_other``; by default the side it
    is on) and may close to ``separation`` (centre to centre) only by ``share`` of the room left
    (1: all of it; 0.5 when the other car obeys the same bound, so that both moving at once
    still keep ``separation``). A car already closer than ``separation`` may not close at all;
    the bounds always contain ``n``.
    """
    if left is None:
        left = n >= n_other
    return keep_clear_of(float(n), float(n_other), float(separation), float(share), bool(left))


@kernel
def keep_clear_of(n, n_other, separation, share, left):
    """:func:`keep_clear` with ``left`` given (inside kernels)."""
    if left:
        return py_min(n, n - share * (n - n_other - separation)), math.inf
    return -math.inf, py_max(n, n + share * (n_other - separation - n))


class EdgeBand:
    """Bands of admissible offsets of a car's reference point on one track.

    ``inner`` [m] is the distance of the soft band from the edges (half the car width plus a
    margin); ``half_width`` and ``half_length`` [m] are the footprint's, for the hard band.
    """

    def __init__(self, track, inner: float, half_width: float, half_length: float):
        self.track = track
        self.inner = float(inner)
        self.half_width = float(half_width)
        self.half_length = float(half_length)
        samples = np.asarray(track.s, float)
        spacing = track.length / len(samples)
        size = 2 * int(math.ceil(_CORNER_WINDOW / spacing)) + 1
        wl = minimum_filter1d(np.asarray(track.width_left(samples), float), size, mode="wrap")
        wr = minimum_filter1d(np.asarray(track.width_right(samples), float), size, mode="wrap")
        self._knots = np.append(samples, track.length)
        wl, wr = np.append(wl, wl[0]), np.append(wr, wr[0])
        self._width_tables = (wl, wr)
        lo, hi = self.inner - wr, wl - self.inner
        mid = 0.5 * (lo + hi)
        self._soft = (np.minimum(lo, mid), np.maximum(hi, mid))  # an empty band collapses to its middle
        length = float(track.length)
        # the trailing arguments of the kernels, built once (the opponents' step passes them every step)
        self._envelope_data = (self._knots, *self._soft, _LOOKAHEAD, _LOOKAHEAD_TIME, length)
        self._hard_data = (self.half_width, self.half_length, self.half_length ** 2, self._knots, wl, wr, length,
                           *track.table("kappa"))

    def widths(self, s: float) -> tuple[float, float]:
        """Smallest left and right widths within the corner window around ``s`` [m] (Python floats;
        :func:`_widths`)."""
        return _widths(float(s), self._knots, *self._width_tables, float(self.track.length))

    def soft(self, s) -> tuple[np.ndarray, np.ndarray]:
        """The soft band ``(lo, hi)`` at ``s`` (an array): the footprint ``inner`` inside both edges."""
        s = np.mod(np.asarray(s, float), self.track.length)
        return interp(s, self._knots, self._soft[0]), interp(s, self._knots, self._soft[1])  # np.interp

    def envelope(self, s: float, v: float, lateral_speed: float, lateral_accel: float) -> tuple[float, float]:
        """The soft band at ``s`` tightened so that a car at speed ``v`` [m/s] that starts moving back
        from rest (accelerating at ``lateral_accel`` [m/s^2] up to ``lateral_speed`` [m/s]) stays inside
        it as it narrows ahead (looking 8 s or at least 50 m ahead). One compiled call (:func:`envelope_at`)."""
        return envelope_at(float(s), float(v), float(lateral_speed), float(lateral_accel), *self.envelope_data())

    def room(self, s: float, distance: float) -> float:
        """Narrowest width of the soft band over ``[s, s + distance]`` [m] (sampled every <= 5 m;
        :func:`room_at`)."""
        return room_at(float(s), float(distance), self._knots, self._soft[0], self._soft[1], float(self.track.length))

    def hard(self, s: float, heading: float) -> tuple[float, float]:
        """The hard band at ``s`` for a car at ``heading`` [rad] to the raceline: every corner inside
        (the footprint's reach across the track at that heading, plus its bulge on a curve; :func:`hard_at`)."""
        return hard_at(float(s), float(heading), *self.hard_data())

    def envelope_data(self) -> tuple:
        """The trailing arguments of :func:`envelope_at` (for kernels): ``knots, soft lo, soft hi, look-ahead
        fractions, look-ahead time, length``."""
        return self._envelope_data

    def hard_data(self) -> tuple:
        """The trailing arguments of :func:`hard_at` (for kernels): ``half_width, half_length,
        half_length ** 2, knots, width_left, width_right, length, curvature knots, curvature``."""
        return self._hard_data


@kernel
def envelope_at(s, v, lateral_speed, lateral_accel, knots, soft_lo, soft_hi, lookahead, lookahead_time, length):
    """:meth:`EdgeBand.envelope`: at the points ``s + d``, ``d = max(lookahead_time v, 50) lookahead``, the soft
    band widened by the room ``back`` a car gains by moving back from rest in the time ``d / max(v, 1e-3)`` it
    takes to get there (``a t^2 / 2`` while accelerating, then ``u t - u t_ramp / 2``); the largest lower and
    the smallest upper bound (their middle if they cross). Python's ``max`` picks and numpy's arithmetic."""
    x = lookahead_time * v
    reach = max(x, 50.0)
    v_div = max(v, 0.001)
    u = lateral_speed
    a = max(lateral_accel, 1e-09)
    t_ramp = u / a
    lo_e, hi_e = -np.inf, np.inf
    j = -1
    for k in range(lookahead.shape[0]):
        d = reach * lookahead[k]
        p = (s + d) % length
        j = locate(p, knots, j)
        t = d / v_div
        back = 0.5 * a * t * t if t < t_ramp else u * t - 0.5 * u * t_ramp
        lo_e = maximum(lo_e, interp_located(j, p, knots, soft_lo) - back)  # np.max
        hi_e = minimum(hi_e, interp_located(j, p, knots, soft_hi) + back)  # np.min
    if lo_e > hi_e:
        lo_e = hi_e = 0.5 * (lo_e + hi_e)
    return lo_e, hi_e


@kernel
def _widths(s, knots, wl, wr, length):
    """:meth:`EdgeBand.widths`: the widths at ``s`` wrapped into [0, length) (floor modulo), on the piece of
    the last knot <= s, as ``w_k + t (w_{k+1} - w_k)``."""
    s = floor_mod(s, length)
    k = min(max(locate(s, knots, -1), 0), knots.shape[0] - 2)
    t = (s - knots[k]) / (knots[k + 1] - knots[k])
    return wl[k] + t * (wl[k + 1] - wl[k]), wr[k] + t * (wr[k + 1] - wr[k])


@kernel
def hard_at(s, heading, half_width, half_length, half_length_sq, knots, wl, wr, length, kappa_knots, kappa):
    """:meth:`EdgeBand.hard` (its trailing arguments: :meth:`EdgeBand.hard_data`)."""
    c, sn = abs(math.cos(heading)), abs(math.sin(heading))
    # the corners half a length ahead and behind sit kappa l^2 / 2 further out on a curve
    bend = 0.5 * abs(lerp_wrapped(s, length, kappa_knots, kappa)) * half_length_sq
    reach = half_width * c + half_length * sn + bend + _HARD_SLACK
    w_l, w_r = _widths(s, knots, wl, wr, length)
    lo, hi = reach - w_r, w_l - reach
    if lo <= hi:
        return lo, hi
    mid = 0.5 * (lo + hi)
    return mid, mid


@kernel
def room_at(s, distance, knots, soft_lo, soft_hi, length):
    """:meth:`EdgeBand.room` (``knots, soft_lo, soft_hi``: the soft band's table): the band's width at
    ``k = min(ceil(max(distance, 0) / 5) + 1, 400)`` points spread as ``np.linspace(0, max(distance, 0), k)``
    computes them (``i * step``, the last one ``stop``), added to ``s`` and wrapped (floor modulo), interpolated
    as ``np.interp``; the smallest (a nan propagates, as ``np.min``)."""
    stop = py_max(distance, 0.0)
    k = min(int(math.ceil(stop / 5.0)) + 1, _ROOM_SAMPLES)
    div = k - 1
    step = stop / div if div > 0 else 0.0
    out = np.inf
    j = -1
    for i in range(k):
        if div <= 0:
            y = float(i) * stop
        elif step == 0.0:
            y = float(i) / div * stop
        else:
            y = float(i) * step
        y = y + 0.0
        if div > 0 and i == k - 1:
            y = stop
        p = floor_mod(s + y, length)
        j = locate(p, knots, j)
        width = interp_located(j, p, knots, soft_hi) - interp_located(j, p, knots, soft_lo)
        out = width if i == 0 else minimum(out, width)
    return out
