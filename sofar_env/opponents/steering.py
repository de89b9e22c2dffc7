"""One lateral step of the whole opponent field (used when a behaviour is on).

For every car, from the start-of-step state of the field and the cars' new arc
lengths and speeds:

1. its *intent*: the defence target with the defence bounds while it defends
   (:class:`~sofar_env.opponents.defence.Defence`, whose state machine advances
   here), else its line with its feed-forward rate and the line bounds; the lateral
   speed is also at most ``v tan(0.1 rad)`` at all times (a slow car does not crab,
   a car braking hard loses its lateral speed with it);
2. its soft envelope (the edge band with look-ahead), tightened so that a car
   beside it has room on its far side: a car pressed toward a neighbour by the
   edge pushes the neighbour's envelope away;
3. its keep-clear bounds (:func:`~sofar_env.opponents.lateral.keep_clear`) on the
   target: half the room down to ``band_margin`` side to side from each opponent
   within ``side_window``, and ``clearance`` from the ego while the ego is alongside
   or about to be (within ``guard_time``), both ``BRAKE_LEAD`` earlier at the
   relative speed, so that the tracker brakes in time; when they conflict with the
   envelope, the target is the point of the keep-clear bounds nearest to it, and the
   car is *squeezed* (the traffic rules make it drop back in the next step);
4. the tracker step toward the target, then the bounds on the position: every
   corner on the track first, then ``HARD_GAP`` side to side from each opponent
   within ``side_window`` and ``clearance`` from the ego within ``guard_time``; a
   car that would cross one stops there (a *clamp*: the acceleration bound yields
   to safety; rare).
"""

from __future__ import annotations

import math

import numpy as np

from .config import OpponentConfig
from .defence import IDLE, ego_guarded
from .lateral import EdgeBand, keep_clear, track_target

__all__ = ["MAX_HEADING_TAN", "BRAKE_LEAD", "HARD_GAP", "steer"]

MAX_HEADING_TAN = math.tan(0.1)
"""Lateral speed bound relative to the arc-length speed: the lateral motion never turns a car more
than 0.1 rad from the raceline heading."""

BRAKE_LEAD = 1.0
"""The keep-clear bounds apply to the target this long [s] (at the relative speed) before they apply to
the position, so that a car moving sideways has stopped by then (at 1.5 m/s and 3 m/s^2: in 0.5 s)."""

HARD_GAP = 0.3
"""Side-to-side gap between two opponents' footprints that the position bounds keep [m] (the target
bounds keep ``band_margin``)."""


def steer(dt: float, ego, state: tuple[list, list, list, list], gap: np.ndarray, s_new: list, v_new: list,
          episode, band: EdgeBand, cfg: OpponentConfig, vehicle) -> tuple[list[float], list[float], int, list[bool]]:
    """New offsets and lateral rates of every car, the number of clamps, and which cars are squeezed
    (their envelope and keep-clear bounds conflict: they will not fit beside the car or ego next to them).

    ``state``: the start-of-step ``(s, n, n_dot, v)`` lists; ``gap[i, j] = s_j - s_i``; ``s_new``,
    ``v_new``: the new arc lengths and speeds; ``ego``: ``(s, n, v)``, a list of such tuples (the
    controlled cars of a multi-car race) or None. With several, each car defends against the nearest
    one behind it (else the nearest one), and keeps clear of every one alongside or about to be.
    """
    s, n, n_dot, v = state
    m = len(s)
    defence, lines, traffic = episode.defence, episode.lines, cfg.traffic
    sep_soft, sep_hard = vehicle.width + traffic.band_margin, vehicle.width + HARD_GAP
    sep_ego = vehicle.width + cfg.defence.clearance
    # the cars beside each one: within side_window (hard), or about to be within BRAKE_LEAD (soft)
    soft_near, hard_near = [], []
    for i in range(m):
        soft_near.append([j for j in range(m) if j != i
                          and abs(gap[i, j]) < traffic.side_window + abs(v[i] - v[j]) * BRAKE_LEAD])
        hard_near.append([j for j in soft_near[i] if abs(gap[i, j]) < traffic.side_window])

    # 1. intents
    # ego_soft[i] / ego_hard[i]: offsets of the egos car i keeps clear of, at its target / position
    intents, ego_soft, ego_hard = [], [()] * m, [()] * m
    egos = [] if ego is None else [tuple(float(x) for x in e) for e in (ego if isinstance(ego, list) else [ego])]
    for i in range(m):
        if egos:
            rows = [(float(band.track.gap(s[i], s_e)), v_e - v[i], n_e) for s_e, n_e, v_e in egos]
            behind = [r for r in rows if r[0] >= 0.0]
            gap_e, closing, n_e = (min(behind, key=lambda r: r[0]) if behind
                                   else min(rows, key=lambda r: abs(r[0])))
            defence.update(i, gap_e, closing, n[i], n_dot[i], n_e)
            ego_soft[i] = tuple(r[2] for r in rows
                                if ego_guarded(r[0], r[1], cfg.defence, vehicle.length, BRAKE_LEAD))
            ego_hard[i] = tuple(r[2] for r in rows if ego_guarded(r[0], r[1], cfg.defence, vehicle.length))
        if defence.mode[i] != IDLE:
            target, rate = float(defence.target[i]), 0.0
            v_max, a_max = defence.limits(i)
        else:
            target, slope = lines.at(i, s_new[i])
            rate = slope * v_new[i]
            v_max, a_max = cfg.lines.lateral_speed, cfg.lines.lateral_accel
        intents.append((target, rate, min(v_max, MAX_HEADING_TAN * max(min(v[i], v_new[i]), 0.0)), a_max))

    # 2. envelopes, pushed apart by the cars alongside
    env = [band.envelope(s_new[i], v_new[i], 0.5 * intents[i][2], 0.5 * intents[i][3]) for i in range(m)]
    pushed = [list(e) for e in env]
    for i in range(m):
        for j in soft_near[i]:
            if _left_of(i, j, n):
                pushed[i][0] = max(pushed[i][0], env[j][0] + sep_soft)
            else:
                pushed[i][1] = min(pushed[i][1], env[j][1] - sep_soft)

    # 3.-4. keep-clear bounds, tracker, hard bounds
    n_out, nd_out, clamps, squeezed = list(n), list(n_dot), 0, [False] * m
    for i in range(m):
        lo_k, hi_k = _clear_of(i, soft_near[i], n, sep_soft)
        lo_p, hi_p = _clear_of(i, hard_near[i], n, sep_hard)
        for n_e in ego_soft[i]:
            lo_k, hi_k = _tighten(lo_k, hi_k, keep_clear(n[i], n_e, sep_ego))
        for n_e in ego_hard[i]:
            lo_p, hi_p = _tighten(lo_p, hi_p, keep_clear(n[i], n_e, sep_ego))
        target, rate, v_max, a_max = intents[i]
        lo_e, hi_e = pushed[i] if pushed[i][0] <= pushed[i][1] else env[i]
        lo_t, hi_t = max(lo_e, lo_k), min(hi_e, hi_k)
        if lo_t > hi_t:  # the keep-clear bounds win, as close to the envelope as they allow
            squeezed[i] = True
            lo_t = hi_t = min(max(min(max(target, lo_e), hi_e), lo_k), hi_k)
        clipped = min(max(target, lo_t), hi_t)
        if clipped != target or (target <= lo_t and rate < 0.0) or (target >= hi_t and rate > 0.0):
            # a target held at a bound moves with the bound: with an edge band, as it will one step on
            rate = 0.0
            if clipped in env[i] and clipped not in (lo_k, hi_k):
                ahead = band.envelope(s_new[i] + v_new[i] * dt, v_new[i], 0.5 * v_max, 0.5 * a_max)
                rate = (ahead[0 if clipped == env[i][0] else 1] - clipped) / dt
        n_i, nd_i = track_target(n[i], n_dot[i], clipped, rate, v_max, a_max, dt, min(lo_t, n[i]), max(hi_t, n[i]))
        crab = MAX_HEADING_TAN * max(v_new[i], 0.0)
        if abs(nd_i) > crab:  # a car that brakes hard cannot keep its lateral speed
            nd_i = math.copysign(crab, nd_i)
            n_i = n[i] + 0.5 * (n_dot[i] + nd_i) * dt
        along = max(v_new[i] * (1.0 - band.track.curvature(s_new[i]) * n_i), 1e-3)
        lo_h, hi_h = band.hard(s_new[i], math.atan2(abs(nd_i), along))
        lo, hi = max(lo_h, lo_p), min(hi_h, hi_p)
        if lo > hi:  # never leave the track
            lo, hi = lo_h, hi_h
        if not lo <= n_i <= hi:
            n_i, nd_i = min(max(n_i, lo), hi), 0.0
            clamps += 1
        n_out[i], nd_out[i] = n_i, nd_i
    return n_out, nd_out, clamps, squeezed


def _left_of(i: int, j: int, n: list) -> bool:
    """Whether car ``i`` is on the left of car ``j`` (a tie puts the higher index on the left)."""
    return n[i] > n[j] or (n[i] == n[j] and i > j)


def _tighten(lo: float, hi: float, bounds: tuple[float, float]) -> tuple[float, float]:
    return max(lo, bounds[0]), min(hi, bounds[1])


def _clear_of(i: int, others: list, n: list, separation: float) -> tuple[float, float]:
    """Keep-clear bounds of car ``i`` against ``others`` (each of the two takes half the room)."""
    lo, hi = -math.inf, math.inf
    for j in others:
        lo, hi = _tighten(lo, hi, keep_clear(n[i], n[j], separation, share=0.5, left=_left_of(i, j, n)))
    return lo, hi
