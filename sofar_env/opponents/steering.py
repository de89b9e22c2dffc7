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
   car is *squeezed* (the traffic rules make it drop back in the next step); with
   ``TrafficConfig.yield_to_any = False`` only when a car or ego it keeps clear of is
   level with it, ahead of it or faster: dropping back makes no room for a slower
   or standing car behind;
4. the tracker step toward the target, then the bounds on the position: every
   corner on the track first, then ``HARD_GAP`` side to side from each opponent
   within ``side_window`` and ``clearance`` from the ego within ``guard_time``; a
   car that would cross one stops there (a *clamp*: the acceleration bound yields
   to safety; rare).
"""

from __future__ import annotations

import math

import numpy as np

from .._jit import kernel, py_max, py_min
from ..tracks.curve import floor_mod, lerp_wrapped
from .config import OpponentConfig
from .defence import IDLE, defence_step, guarded
from .lateral import EdgeBand, envelope_at, hard_at, keep_clear_of, track_target
from .lines import line_at

__all__ = ["BRAKE_LEAD", "HARD_GAP", "MAX_HEADING_TAN", "steer"]

MAX_HEADING_TAN = math.tan(0.1)
"""Lateral speed bound relative to the arc-length speed: the lateral motion never turns a car more
than 0.1 rad from the raceline heading."""

BRAKE_LEAD = 1.0
"""The keep-clear bounds apply to the target this long [s] (at the relative speed) before they apply to
the position, so that a car moving sideways has stopped by then (at 1.5 m/s and 3 m/s^2: in 0.5 s)."""

HARD_GAP = 0.3
"""Side-to-side gap between two opponents' footprints that the position bounds keep [m] (the target
bounds keep ``band_margin``)."""


def steer(dt: float, ego, state: tuple, gap: np.ndarray, s_new, v_new,
          episode, band: EdgeBand, cfg: OpponentConfig, vehicle) -> tuple[np.ndarray, np.ndarray, int, np.ndarray]:
    """New offsets and lateral rates of every car, the number of clamps, and which cars are squeezed
    (their envelope and keep-clear bounds conflict: they will not fit beside the car or ego next to them).

    ``state``: the start-of-step ``(s, n, n_dot, v)`` arrays (or lists); ``gap[i, j] = s_j - s_i``; ``s_new``,
    ``v_new``: the new arc lengths and speeds; ``ego``: ``(s, n, v)``, a list of such tuples (the
    controlled cars of a multi-car race) or None. With several, each car defends against the nearest
    one behind it (else the nearest one), and keeps clear of every one alongside or about to be.
    The defence state of ``episode`` advances. One compiled call (:func:`_steer`).
    """
    s, n, n_dot, v = (np.asarray(x, dtype=float) for x in state)
    m = s.shape[0]
    if ego is None:
        egos = np.zeros((0, 3))
    else:
        egos = np.array([[float(x) for x in e] for e in (ego if isinstance(ego, list) else [ego])], dtype=float)
        egos = egos.reshape(-1, 3)
    defence, lines, traffic, dcfg = episode.defence, episode.lines, cfg.traffic, cfg.defence
    n_out, nd_out, squeezed = np.empty(m), np.empty(m), np.zeros(m, dtype=np.bool_)
    field = (s, n, n_dot, v, np.ascontiguousarray(gap, dtype=float), np.asarray(s_new, dtype=float),
             np.asarray(v_new, dtype=float))
    defence_state = (defence.aggressiveness, defence.approach, defence.used, defence.mode, defence.target,
                     defence.moves)
    defence_rules = (vehicle.length + dcfg.alongside_margin, dcfg.min_gap, dcfg.max_gap, dcfg.release,
                     dcfg.min_closing, dcfg.trigger, dcfg.guard_time, dcfg.lateral_speed, dcfg.lateral_accel)
    line_data = (bool(lines.active), lines.offsets, lines.a1, lines.a2, lines.w1, lines.w2, lines.p1, lines.p2,
                 cfg.lines.lateral_speed, cfg.lines.lateral_accel)
    spacing = (traffic.side_window, vehicle.width + traffic.band_margin, vehicle.width + HARD_GAP,
               vehicle.width + dcfg.clearance, bool(traffic.yield_to_any))
    clamps = _steer(float(dt), field, egos, defence_state, defence_rules, line_data, spacing, band.envelope_data(),
                    band.hard_data(), (n_out, nd_out, squeezed))
    return n_out, nd_out, int(clamps), squeezed


@kernel
def _steer(dt, field, egos, defence_state, defence_rules, line_data, spacing, band_envelope, band_hard, out):
    """:func:`steer` on arrays (its steps 1-4 in the module docstring, in the order and with the operations of
    the Python form it replaced; ``min``/``max`` as Python's). The inputs come in bundles, one per concept:

    * ``field``: the start-of-step ``(s, n, n_dot, v)``, ``gap`` and the new ``(s_new, v_new)``;
    * ``egos`` (E, 3) rows ``(s, n, v)``;
    * ``defence_state``: :class:`~.defence.Defence`'s arrays ``(aggressiveness, approach, used, mode, target,
      moves)``, changed in place; ``defence_rules``: ``(alongside, min_gap, max_gap, release, min_closing,
      trigger, guard_time, lateral_speed, lateral_accel)``;
    * ``line_data``: ``(active, offsets, a1, a2, w1, w2, p1, p2, lateral_speed, lateral_accel)`` of the lines;
    * ``spacing``: ``(side_window, soft separation, hard separation, separation from an ego, yield_to_any)``
      (``TrafficConfig.yield_to_any``: whether a squeezed car is flagged whoever squeezes it, or only when a car
      or ego it keeps clear of is ahead of it, level, or faster);
    * ``band_envelope``, ``band_hard``: :meth:`EdgeBand.envelope_data` and :meth:`EdgeBand.hard_data` (both end
      with the track length);
    * ``out``: ``(n_out, nd_out, squeezed)``, written.

    Returns the clamps."""
    s, n, n_dot, v, gap, s_new, v_new = field
    aggressiveness, approach, used, mode, d_target, moves = defence_state
    (along, min_gap, max_gap, release, min_closing, trigger, guard_time, d_lateral_speed,
     d_lateral_accel) = defence_rules
    lines_active, offsets, a1, a2, w1, w2, p1, p2, l_lateral_speed, l_lateral_accel = line_data
    side_window, sep_soft, sep_hard, sep_ego, yield_to_any = spacing
    soft_knots, soft_lo, soft_hi, lookahead, lookahead_time, length = band_envelope
    half_width, half_length, half_length_sq, knots, wl, wr, hard_length, kappa_knots, kappa = band_hard
    n_out, nd_out, squeezed = out
    m = s.shape[0]
    n_egos = egos.shape[0]
    # the cars beside each one: within side_window (hard), or about to be within BRAKE_LEAD (soft)
    soft_near = np.zeros((m, m), dtype=np.bool_)
    hard_near = np.zeros((m, m), dtype=np.bool_)
    for i in range(m):
        for j in range(m):
            if j != i and abs(gap[i, j]) < side_window + abs(v[i] - v[j]) * BRAKE_LEAD:
                soft_near[i, j] = True
                hard_near[i, j] = abs(gap[i, j]) < side_window

    # 1. intents; ego_soft[i, e] / ego_hard[i, e]: car i keeps clear of ego e at its target / position
    target = np.empty(m)
    rate = np.empty(m)
    v_lim = np.empty(m)
    a_lim = np.empty(m)
    ego_soft = np.zeros((m, n_egos), dtype=np.bool_)
    ego_hard = np.zeros((m, n_egos), dtype=np.bool_)
    ego_passing = np.zeros((m, n_egos), dtype=np.bool_)  # ego e is level with or ahead of car i, or faster
    half = 0.5 * length
    for i in range(m):
        if n_egos > 0:
            best, best_key, best_behind, best_gap, best_closing = -1, 0.0, False, 0.0, 0.0
            for e in range(n_egos):
                r = floor_mod(s[i] - egos[e, 0] + half, length)
                g = (0.0 if r >= length else r) - half
                closing = egos[e, 2] - v[i]
                behind = g >= 0.0
                # the nearest ego behind the car, else the nearest one (the first of equals)
                key = g if behind else abs(g)
                if best < 0 or (behind and not best_behind) or (behind == best_behind and key < best_key):
                    best, best_key, best_behind, best_gap, best_closing = e, key, behind, g, closing
                ego_passing[i, e] = g <= 0.0 or closing > 0.0
                ego_soft[i, e] = guarded(g, closing, along, guard_time, BRAKE_LEAD)
                ego_hard[i, e] = guarded(g, closing, along, guard_time, 0.0)
            defence_step(i, best_gap, best_closing, n[i], n_dot[i], egos[best, 1], aggressiveness, approach, used,
                         mode, d_target, moves, along, min_gap, max_gap, release, min_closing, trigger)
        if mode[i] != IDLE:
            target[i], rate[i] = d_target[i], 0.0
            v_max, a_lim[i] = aggressiveness[i] * d_lateral_speed, d_lateral_accel
        else:
            if lines_active:
                target[i], slope = line_at(s_new[i], offsets[i], a1[i], a2[i], w1[i], w2[i], p1[i], p2[i])
            else:
                target[i], slope = offsets[i], 0.0
            rate[i] = slope * v_new[i]
            v_max, a_lim[i] = l_lateral_speed, l_lateral_accel
        v_lim[i] = py_min(v_max, MAX_HEADING_TAN * py_max(py_min(v[i], v_new[i]), 0.0))

    # 2. envelopes, pushed apart by the cars alongside
    env_lo = np.empty(m)
    env_hi = np.empty(m)
    for i in range(m):
        env_lo[i], env_hi[i] = envelope_at(s_new[i], v_new[i], 0.5 * v_lim[i], 0.5 * a_lim[i], soft_knots, soft_lo,
                                         soft_hi, lookahead, lookahead_time, length)
    push_lo = env_lo.copy()
    push_hi = env_hi.copy()
    for i in range(m):
        for j in range(m):
            if soft_near[i, j]:
                if _left_of(i, j, n):
                    push_lo[i] = py_max(push_lo[i], env_lo[j] + sep_soft)
                else:
                    push_hi[i] = py_min(push_hi[i], env_hi[j] - sep_soft)

    # 3.-4. keep-clear bounds, tracker, hard bounds
    clamps = 0
    for i in range(m):
        lo_k, hi_k = _clear_of(i, soft_near, n, sep_soft)
        lo_p, hi_p = _clear_of(i, hard_near, n, sep_hard)
        for e in range(n_egos):
            if ego_soft[i, e]:
                lo, hi = keep_clear_of(n[i], egos[e, 1], sep_ego, 1.0, n[i] >= egos[e, 1])
                lo_k, hi_k = py_max(lo_k, lo), py_min(hi_k, hi)
        for e in range(n_egos):
            if ego_hard[i, e]:
                lo, hi = keep_clear_of(n[i], egos[e, 1], sep_ego, 1.0, n[i] >= egos[e, 1])
                lo_p, hi_p = py_max(lo_p, lo), py_min(hi_p, hi)
        tgt, rt, v_max, a_max = target[i], rate[i], v_lim[i], a_lim[i]
        if push_lo[i] <= push_hi[i]:
            lo_e, hi_e = push_lo[i], push_hi[i]
        else:
            lo_e, hi_e = env_lo[i], env_hi[i]
        lo_t, hi_t = py_max(lo_e, lo_k), py_min(hi_e, hi_k)
        squeezed[i] = False
        if lo_t > hi_t:  # the keep-clear bounds win, as close to the envelope as they allow
            squeezed[i] = yield_to_any or _yields(i, soft_near, gap, v, ego_soft, ego_passing)
            lo_t = py_min(py_max(py_min(py_max(tgt, lo_e), hi_e), lo_k), hi_k)
            hi_t = lo_t
        clipped = py_min(py_max(tgt, lo_t), hi_t)
        if clipped != tgt or (tgt <= lo_t and rt < 0.0) or (tgt >= hi_t and rt > 0.0):
            # a target held at a bound moves with the bound: with an edge band, as it will one step on
            rt = 0.0
            if (clipped == env_lo[i] or clipped == env_hi[i]) and not (clipped == lo_k or clipped == hi_k):
                ahead_lo, ahead_hi = envelope_at(s_new[i] + v_new[i] * dt, v_new[i], 0.5 * v_max, 0.5 * a_max,
                                               soft_knots, soft_lo, soft_hi, lookahead, lookahead_time, length)
                rt = ((ahead_lo if clipped == env_lo[i] else ahead_hi) - clipped) / dt
        n_i, nd_i = track_target(n[i], n_dot[i], clipped, rt, v_max, a_max, dt, py_min(lo_t, n[i]),
                                 py_max(hi_t, n[i]))
        crab = MAX_HEADING_TAN * py_max(v_new[i], 0.0)
        if abs(nd_i) > crab:  # a car that brakes hard cannot keep its lateral speed
            nd_i = math.copysign(crab, nd_i)
            n_i = n[i] + 0.5 * (n_dot[i] + nd_i) * dt
        along_s = py_max(v_new[i] * (1.0 - lerp_wrapped(s_new[i], length, kappa_knots, kappa) * n_i), 1e-3)
        lo_h, hi_h = hard_at(s_new[i], math.atan2(abs(nd_i), along_s), half_width, half_length, half_length_sq, knots,
                           wl, wr, hard_length, kappa_knots, kappa)
        lo, hi = py_max(lo_h, lo_p), py_min(hi_h, hi_p)
        if lo > hi:  # never leave the track
            lo, hi = lo_h, hi_h
        if not lo <= n_i <= hi:
            n_i, nd_i = py_min(py_max(n_i, lo), hi), 0.0
            clamps += 1
        n_out[i], nd_out[i] = n_i, nd_i
    return clamps


@kernel
def _yields(i, soft_near, gap, v, ego_soft, ego_passing):
    """Whether squeezed car ``i`` has a reason to drop back: a car it keeps clear of is level with or ahead of it
    or faster than it, or such an ego (``ego_passing``). Dropping back behind a slower or standing car behind it
    makes no room (``TrafficConfig.yield_to_any = False``)."""
    for j in range(soft_near.shape[1]):
        if soft_near[i, j] and (gap[i, j] >= 0.0 or v[j] > v[i]):
            return True
    for e in range(ego_soft.shape[1]):
        if ego_soft[i, e] and ego_passing[i, e]:
            return True
    return False


@kernel
def _left_of(i, j, n):
    """Whether car ``i`` is on the left of car ``j`` (a tie puts the higher index on the left)."""
    return n[i] > n[j] or (n[i] == n[j] and i > j)


@kernel
def _clear_of(i, near, n, separation):
    """Keep-clear bounds of car ``i`` against the cars ``j`` with ``near[i, j]`` (each of the two takes half
    the room)."""
    lo, hi = -math.inf, math.inf
    for j in range(n.shape[0]):
        if near[i, j]:
            b_lo, b_hi = keep_clear_of(n[i], n[j], separation, 0.5, _left_of(i, j, n))
            lo, hi = py_max(lo, b_lo), py_min(hi, b_hi)
    return lo, hi
