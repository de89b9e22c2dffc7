"""The 12-value observation of the paper, in the global Frenet frame of the raceline.

Every value is a physical quantity clipped to a documented range ``[lo, hi]`` and
mapped affinely onto ``[-1, 1]``: ``o = 2 (clip(x, lo, hi) - lo) / (hi - lo) - 1``
(for a symmetric range this is ``x / hi``). There are no sentinels: an absent
opponent reads as "far", i.e. gap = 200 m (o = +1), n = 0, closing speed = 0.

======  =====================  ======  ==============  =================================================
index   quantity               unit    range [lo, hi]  definition
======  =====================  ======  ==============  =================================================
0       ego n                  m       [-15, 15]       lateral offset from the raceline, + left
1       ego v                  m/s     [0, 100]        plant speed
2       steering delta         rad     [-0.25, 0.25]   steering angle of the plant
3, 4    gap 1, gap 2           m       [-20, 200]      s_opp - s_ego of the two nearest opponents with a
                                                       gap in [-20, 200] m, ascending (so a car alongside
                                                       or just behind comes first); 200 if absent
5, 6    n 1, n 2               m       [-15, 15]       their lateral offsets; 0 if absent
7, 8    dv 1, dv 2             m/s     [-50, 50]       closing speeds v_ego - v_opp (arc-length speeds);
                                                       0 if absent
9       mean curvature         1/m     [-0.05, 0.05]   raceline curvature averaged over the next 1.5 s
                                                       at the ego's speed (16 samples, at least 5 m/s)
10, 11  width left / right     m       [0, 15]         raceline-to-edge distances at the ego's s
======  =====================  ======  ==============  =================================================

"Opponents" are whatever the car must avoid: the scripted opponents and, in the
multi-agent environment, the other active cars (:meth:`Race.opponent_frenet`).

The **extended** observation (``EnvConfig.observation = "extended"``, the default of the
interactive world) appends four values a good gamma depends on when opponents move and are
sensed with noise (16 in all):

======  =====================  ======  ==============  =================================================
index   quantity               unit    range [lo, hi]  definition
======  =====================  ======  ==============  =================================================
12, 13  n_dot 1, n_dot 2       m/s     [-3, 3]         lateral rates of opponents 1 and 2 (the tracker
                                                       estimate of :mod:`sofar_env.sensing`; 0 without a
                                                       sensor or if absent)
14      heading error e        rad     [-0.5, 0.5]     ego heading minus the raceline's
15      smallest barrier h     -       [-1, 9]         the barrier value of the nearest-in-h opponent
                                                       as sensed (:func:`~sofar_env.control.barrier.
                                                       min_barrier`): the instantaneous safety margin;
                                                       9 (far) if absent
======  =====================  ======  ==============  =================================================
"""

from __future__ import annotations

import math

import numpy as np

from ._interp import interp_located, locate
from ._jit import kernel, maximum, minimum
from .tracks import Track
from .tracks.curve import floor_mod

__all__ = ["OBS_NAMES", "OBS_LOW", "OBS_HIGH", "EXTENDED_NAMES", "EXTENDED_LOW", "EXTENDED_HIGH", "GAP_RANGE",
           "LOOKAHEAD_TIME", "OBSERVATIONS", "observation_size", "observe", "scale"]

OBS_NAMES = (
    "ego_n", "ego_v", "steering", "gap_1", "gap_2", "n_1", "n_2", "dv_1", "dv_2",
    "mean_curvature", "width_left", "width_right",
)
GAP_RANGE = (-20.0, 200.0)
"""Opponents with a gap in this window [m] are observed; an absent one reads as the upper end."""
LOOKAHEAD_TIME = 1.5
"""Horizon of the mean curvature [s] (that of the MPC: 20 x 0.075 s)."""
_CURV_SAMPLES = 16
_MIN_LOOKAHEAD_SPEED = 5.0  # [m/s]

OBS_LOW = np.array([-15.0, 0.0, -0.25, GAP_RANGE[0], GAP_RANGE[0], -15.0, -15.0, -50.0, -50.0, -0.05, 0.0, 0.0])
"""Physical lower ends of the clip ranges, per index."""
OBS_HIGH = np.array([15.0, 100.0, 0.25, GAP_RANGE[1], GAP_RANGE[1], 15.0, 15.0, 50.0, 50.0, 0.05, 15.0, 15.0])
"""Physical upper ends of the clip ranges, per index."""
_SPAN = OBS_HIGH - OBS_LOW
OBSERVATIONS: tuple[str, ...] = ("paper", "extended")
"""Names of the observation layouts (``EnvConfig.observation``)."""
EXTENDED_NAMES = OBS_NAMES + ("n_dot_1", "n_dot_2", "heading_error", "barrier_min")
EXTENDED_LOW = np.concatenate([OBS_LOW, [-3.0, -3.0, -0.5, -1.0]])
"""Physical lower ends of the extended observation's clip ranges."""
EXTENDED_HIGH = np.concatenate([OBS_HIGH, [3.0, 3.0, 0.5, 9.0]])
"""Physical upper ends of the extended observation's clip ranges."""
_EXT_LOW, _EXT_HIGH, _EXT_SPAN = EXTENDED_LOW[12:], EXTENDED_HIGH[12:], EXTENDED_HIGH[12:] - EXTENDED_LOW[12:]


def observation_size(layout: str) -> int:
    """Number of values of the observation ``layout`` (``"paper"``: 12, ``"extended"``: 16)."""
    if layout not in OBSERVATIONS:
        raise ValueError(f"unknown observation {layout!r}; valid: {', '.join(OBSERVATIONS)}")
    return len(OBS_NAMES) if layout == "paper" else len(EXTENDED_NAMES)
_TAU = np.linspace(0.0, LOOKAHEAD_TIME, _CURV_SAMPLES)


def scale(raw) -> np.ndarray:
    """Physical values (..., 12) -> observation in [-1, 1] (float32)."""
    if type(raw) is np.ndarray and raw.shape == (12,) and raw.dtype == np.float64:  # one observation
        out = np.empty(12, np.float32)
        _scale_row(raw, OBS_LOW, OBS_HIGH, _SPAN, out)
        return out
    out = np.maximum(np.asarray(raw, float), OBS_LOW)
    # 2 (clip(raw) - lo) / span - 1, in place
    np.minimum(out, OBS_HIGH, out=out)
    out -= OBS_LOW
    out *= 2.0
    out /= _SPAN
    out -= 1.0
    return out.astype(np.float32)


def raw_observation(track, ego_frenet, opponents) -> np.ndarray:
    """The 12 physical values (float64) for an ego Frenet state (s, n, e, v, delta) and opponent rows (s, n, v)."""
    s, n, _, v, delta = map(float, ego_frenet)
    lo, hi = GAP_RANGE
    # a scalar loop over the (few) opponents: the track's scalar gap is the fast path
    seen = []
    for s_o, n_o, v_o in np.asarray(opponents, float).reshape(-1, 3).tolist():
        g = track.gap(s_o, s)
        if lo <= g <= hi:
            seen.append((g, n_o, v - v_o))
    seen.sort(key=lambda row: row[0])
    seen += [(hi, 0.0, 0.0)] * (2 - len(seen))
    (g1, n1, dv1), (g2, n2, dv2) = seen[:2]
    kappa = _mean_curvature(track, s, max(v, _MIN_LOOKAHEAD_SPEED))
    return np.array([n, v, delta, g1, g2, n1, n2, dv1, dv2, kappa, track.width_left(s), track.width_right(s)])


def _mean_curvature(track, s: float, speed: float) -> float:
    """Mean raceline curvature [1/m] over the look-ahead: ``track.curvature(s + speed * _TAU).sum() / 16``.
    For a :class:`~sofar_env.tracks.Track` one compiled call (:func:`_curvature_sum`, the same bits); any
    other object with the track's ``curvature`` (a test's closed-form circuit) through it."""
    if isinstance(track, Track):
        knots, table = track.table("kappa")
        return _curvature_sum(s, speed, _TAU, track.length, knots, table) / _CURV_SAMPLES
    return float(np.add.reduce(np.asarray(track.curvature(s + speed * _TAU), float))) / _CURV_SAMPLES


def extra_observation(track, ego_frenet, opponents, barrier_params, min_h: float | None = None) -> np.ndarray:
    """The four physical values (float64) the extended observation appends, for opponent rows (s, n, v[, n_dot]);
    ``min_h``: :func:`~sofar_env.control.barrier.min_barrier` of these very arguments where the caller has it
    already (None: computed here)."""
    from .control.barrier import min_barrier

    s = float(ego_frenet[0])
    lo, hi = GAP_RANGE
    rows = np.asarray(opponents, float)
    rows = rows.reshape(-1, rows.shape[-1] if rows.ndim == 2 and rows.shape[-1] == 4 else 3)
    seen = []
    for row in rows.tolist():
        g = track.gap(row[0], s)
        if lo <= g <= hi:
            seen.append((g, row[3] if len(row) == 4 else 0.0))
    seen.sort(key=lambda r: r[0])
    seen += [(hi, 0.0)] * (2 - len(seen))
    if min_h is not None:
        h = min_h
    else:
        h = min_barrier(track, ego_frenet, rows, barrier_params) if len(rows) else np.inf
    return np.array([seen[0][1], seen[1][1], float(ego_frenet[2]), min(h, EXTENDED_HIGH[15])])


def observe(race, car: int = 0, opponents: np.ndarray | None = None, layout: str = "paper",
            barrier_params=None, min_h: float | None = None) -> np.ndarray:
    """Observation (12,) or, with ``layout="extended"``, (16,) float32 of controlled car ``car`` of ``race``.

    ``opponents`` may pass ``race.opponent_frenet(car)`` when the caller has it already (rows (s, n, v), or
    (s, n, v, n_dot) with a sensor's lateral rates); ``barrier_params`` (the MPC's
    :class:`~sofar_env.control.barrier.BarrierParams`) are needed for the extended layout, and ``min_h`` may pass
    the car's smallest barrier value against these rows with these parameters (:func:`extra_observation`).
    """
    if opponents is None:
        opponents = race.opponent_frenet(car)
    if layout == "paper":
        return scale(raw_observation(race.track, race.frenet[car], opponents))
    opponents = np.asarray(opponents, float)
    out = np.empty(16, np.float32)
    _scale_row(raw_observation(race.track, race.frenet[car], opponents[:, :3]), OBS_LOW, OBS_HIGH, _SPAN, out[:12])
    extra = extra_observation(race.track, race.frenet[car], opponents, barrier_params, min_h)
    _scale_clipped(extra, _EXT_LOW, _EXT_HIGH, _EXT_SPAN, out[12:])  # 2 (clip(extra) - lo) / span - 1
    return out


@kernel
def _scale_row(raw, low, high, span, out):
    """:func:`scale` of one observation (1-D float arrays) into the float32 ``out``, compiled (one call instead
    of seven numpy calls): ``(clip(raw, low, high) - low) * 2 / span - 1`` in that order (np.maximum then
    np.minimum: a nan stays nan), rounded to float32."""
    for i in range(raw.shape[0]):
        c = minimum(maximum(raw[i], low[i]), high[i])
        out[i] = (c - low[i]) * 2.0 / span[i] - 1.0


@kernel
def _curvature_sum(s, speed, tau, length, knots, table):
    """``np.add.reduce(np.interp(np.mod(s + speed * tau, length), knots, table))`` for 8 to 128 points ``tau``:
    the interpolation of :func:`~sofar_env._interp.interp_located` and numpy's pairwise sum of that size (eight
    running sums over blocks of eight, ``((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))``, then the rest
    one by one), so numpy's bits."""
    n = tau.shape[0]
    vals = np.empty(n)
    j = -1
    for i in range(n):
        p = floor_mod(s + speed * tau[i], length)
        j = locate(p, knots, j)
        vals[i] = interp_located(j, p, knots, table)
    r = vals[:8].copy()
    i = 8
    while i < n - n % 8:
        for k in range(8):
            r[k] += vals[i + k]
        i += 8
    total = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]))
    while i < n:
        total += vals[i]
        i += 1
    return total


@kernel
def _scale_clipped(raw, low, high, span, out):
    """``2 (np.clip(raw, low, high) - low) / span - 1`` of 1-D float arrays into the float32 ``out``, compiled
    (the extended observation's four values): np.clip's float rule (a nan stays nan; ``x > low ? x : low``,
    then ``x < high ? x : high``) and the operations in that order, rounded to float32."""
    for i in range(raw.shape[0]):
        c = raw[i]
        if not math.isnan(c):  # the ternaries are np.clip's rule (Python's max/min pick differently at ties)
            c = c if c > low[i] else low[i]  # noqa: FURB136
            c = c if c < high[i] else high[i]  # noqa: FURB136
        out[i] = 2.0 * (c - low[i]) / span[i] - 1.0
