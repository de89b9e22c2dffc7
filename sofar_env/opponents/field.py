"""The opponent field on one track: motion, overtakes and respawn, poses.

With every behaviour off (the default, the paper's field) each opponent drives
along the raceline at a constant lateral offset ``n`` [m] with arc-length speed
``ds/dt = rho * v_profile(s)`` [m/s] (midpoint rule), ignoring the ego and each
other; no random number is drawn.

With a behaviour on (:class:`~sofar_env.opponents.config.OpponentConfig`) every
step moves each car

* along the track at ``pace_i * lift_i(t) * v_profile(s)``
  (:mod:`~sofar_env.opponents.pace`), within the traffic rules among opponents
  (:mod:`~sofar_env.opponents.traffic`: following, passing where two cars fit,
  yielding);
* across the track toward its target offset, the ego's offset of its one
  defensive move (:mod:`~sofar_env.opponents.defence`) or else its own line
  (:mod:`~sofar_env.opponents.lines`), with bounded lateral speed and
  acceleration, inside the edges, clear of the other opponents and, while the ego
  is (about to be) alongside, of the ego (:mod:`~sofar_env.opponents.steering`).

All random numbers come from two generators seeded from the ``rng`` given to
:meth:`Opponents.reset` (one for the per-episode parameters, one for the lift
times), in a fixed order: a seed draws the same paces, lines and aggressiveness whichever
behaviours are on.

Overtakes. For every opponent the signed gap to the ego, ``s_opp - s_ego`` [m],
is tracked *unwrapped* (increments of the periodic gap are accumulated), so a
car that falls half a lap behind is never mistaken for one just passed. An
opponent that has been ahead (gap > 0) and then falls ``overtake_threshold``
behind is counted once and respawned ``respawn_distance`` ahead of the ego (the
spot is moved further ahead while it would overlap another opponent on the
same side; any other opponent when a behaviour is on), with a new identity
(``ids``) and fresh per-approach state.
"""

from __future__ import annotations

import numpy as np

from .._jit import kernel, py_min
from ..tracks.curve import floor_mod, lerp_wrapped
from ..vehicle import AV21, VehicleParams
from .config import OpponentConfig
from .defence import IDLE, Defence
from .lateral import EdgeBand
from .lines import Lines
from .pace import LiftSchedule, draw_paces, lift_factor_at
from .steering import MAX_HEADING_TAN, steer
from .traffic import limit_advances_at

__all__ = ["Opponents"]

class _Episode:
    """Per-episode draws and per-car behaviour state of an interactive field."""

    def __init__(self, cfg: OpponentConfig, offsets: np.ndarray, rho: float, length: float, car_length: float,
                 rng: np.random.Generator):
        m = offsets.shape[0]
        params, lifts = (np.random.default_rng(int(seed)) for seed in rng.integers(0, 2 ** 63, size=2))
        self.pace = draw_paces(rho, m, cfg.pace, params)
        self.lines = Lines(offsets, length, cfg.lines, params)
        self.defence = Defence(m, cfg.defence, params, car_length)
        self.lifts = LiftSchedule(m, cfg.pace, lifts)


class Opponents:
    """State of the opponent field on one track (arrays of length ``count``)."""

    def __init__(self, track, config: OpponentConfig, vehicle: VehicleParams = AV21):
        self.track = track
        self.config = config
        self.vehicle = vehicle
        if config.interactive and not config.traffic.follow_gap > vehicle.length:
            raise ValueError(f"traffic.follow_gap must exceed the car length {vehicle.length} m")
        self.s = np.zeros(0)
        """Arc length [m] in [0, L)."""
        self.n = np.zeros(0)
        """Lateral offset [m]."""
        self.v = np.zeros(0)
        """Arc-length speed ds/dt [m/s]."""
        self.n_dot = np.zeros(0)
        """Lateral rate dn/dt [m/s] (0 with the behaviours off)."""
        self.rel = np.zeros(0)
        """Unwrapped gap to the ego, s_opp - s_ego [m] (> 0 ahead)."""
        self.was_ahead = np.zeros(0, bool)
        self.ids = np.zeros(0, int)
        """Identity of each car: a respawned car gets a new one."""
        self.rho = 0.0
        self.time = 0.0
        """Time since the reset [s]."""
        self.clamps = 0
        """Lateral positions stopped at a hard bound since the reset (a diagnostic; rare)."""
        self._next_id = 0
        self._episode: _Episode | None = None
        self._squeezed = np.zeros(0, dtype=np.bool_)
        self._band: EdgeBand | None = None
        self._pose_cache: tuple | None = None
        self._speed_table = track.table("v")

    @property
    def count(self) -> int:
        return int(self.s.shape[0])

    @property
    def squeezed(self) -> np.ndarray:
        """(count,) whether each car was squeezed in the last step, so that it brakes in the next
        (:mod:`~sofar_env.opponents.steering`; all False with the behaviours off). A copy."""
        return self._squeezed.copy() if len(self._squeezed) == self.count else np.zeros(self.count, dtype=bool)

    @property
    def episode(self) -> _Episode | None:
        """Per-episode draws (paces, lines, defence state, lifts); None with the behaviours off."""
        return self._episode

    def reset(self, ego_s: float, rho: float | None = None, n_opponents: int | None = None,
              rng: np.random.Generator | None = None) -> None:
        """Place the opponents at their configured gaps ahead of the ego.

        ``rng`` is used only when a behaviour is on (and then required).
        """
        cfg = self.config
        m = cfg.n_opponents if n_opponents is None else int(n_opponents)
        if m < 0:
            raise ValueError("n_opponents must be >= 0")
        self.rho = cfg.rho if rho is None else float(rho)
        if not (0.0 <= self.rho <= 2.0):
            raise ValueError(f"rho must lie in [0, 2], got {self.rho}")
        gaps = np.array([cfg.gap(i) for i in range(m)])
        self.n = np.array([cfg.offset(i) for i in range(m)])
        self.s = self.track.wrap(ego_s + gaps) if m else np.zeros(0)
        self.rel = gaps.astype(float)
        self.was_ahead = self.rel > 0.0
        self.n_dot = np.zeros(m)
        self.ids = np.arange(m)
        self._next_id = m
        self.time = 0.0
        self.clamps = 0
        self._episode = None
        self._squeezed = np.zeros(m, dtype=np.bool_)
        if not (cfg.interactive and m):
            self.v = self._speed(self.s)
            return
        if rng is None:
            raise ValueError("an rng is required when an opponent behaviour is on")
        ep = self._episode = _Episode(cfg, self.n, self.rho, self.track.length, self.vehicle.length, rng)
        if self._band is None:
            p = self.vehicle
            self._band = EdgeBand(self.track, 0.5 * p.width + cfg.lines.edge_margin, 0.5 * p.width,
                                  max(p.cg_to_front, p.cg_to_rear))
        self.v = ep.pace * np.asarray(self.track.speed(self.s), float)
        for i in range(m):
            self.n[i] = self._line_start(i)

    def _speed(self, s: np.ndarray) -> np.ndarray:
        if s.size == 0:
            return np.zeros(0)
        return self.rho * np.asarray(self.track.speed(s), float)

    def _line_start(self, i: int) -> float:
        """Offset of car ``i`` at (re)spawn: its line, inside the soft band ahead."""
        s = float(self.s[i])
        n, _ = self._episode.lines.at(i, s)
        v = float(self.v[i])
        lines = self.config.lines
        speed = min(lines.lateral_speed, MAX_HEADING_TAN * v)
        lo, hi = self._band.envelope(s, v, 0.5 * speed, 0.5 * lines.lateral_accel)
        return min(max(n, lo), hi)

    # ------------------------------------------------------------------ motion
    def advance(self, dt: float, ego: tuple[float, float, float] | list | None = None) -> None:
        """Move every opponent ``dt`` [s].

        ``ego`` is ``(s, n, v)`` of the ego at the start of the step (arc length [m], lateral
        offset [m], arc-length speed [m/s]), or a list of such tuples, one per controlled car of a
        multi-car race; it is used only when a behaviour is on.
        """
        if self.count == 0:
            self.time += dt
            return
        if self._episode is not None:
            self._advance_interactive(dt, ego)
            self.time += dt
            return
        knots, table = self._speed_table
        s, v = np.empty(self.count), np.empty(self.count)
        _advance_on_profile(self.s, float(self.rho), float(dt), self.track.length, knots, table, s, v)
        self.s, self.v = s, v
        self.time += dt

    def _advance_interactive(self, dt: float, ego) -> None:
        track, cfg, ep, t = self.track, self.config, self._episode, self.time
        m = self.count
        ep.lifts.advance(t + dt)
        gap = np.asarray(track.gap(self.s[None, :], self.s[:, None]), float).reshape(m, m)  # [i, j] = s_j - s_i
        pace_cfg = cfg.pace
        s_new, v_new = np.empty(m), np.empty(m)
        # along the track: nominal pace, then the traffic rules (following, passing, yielding)
        _advance_along((self.s, self.n, self.v, gap, self._squeezed), float(t), float(dt),
                       (ep.pace, ep.lifts.start, pace_cfg.lift_duration, pace_cfg.lift_ramp, pace_cfg.lift_depth,
                        *self._speed_table),
                       (cfg.traffic.follow_gap, self.vehicle.width + cfg.traffic.band_margin,
                        self.vehicle.length + cfg.defence.alongside_margin),
                       self._band.envelope_data(), (s_new, v_new))
        # across the track
        n_new, n_dot_new, clamps, self._squeezed = steer(dt, ego, (self.s, self.n, self.n_dot, self.v), gap, s_new,
                                                         v_new, ep, self._band, cfg, self.vehicle)
        self.clamps += clamps
        self.s, self.v = s_new, v_new
        self.n, self.n_dot = n_new, n_dot_new

    # ------------------------------------------------------------------ overtakes
    def update_overtakes(self, ego_s: float) -> np.ndarray:
        """Update the gaps after a step; count and respawn overtaken opponents.

        Returns the indices of the opponents overtaken in this step.
        """
        if self.count == 0:
            return np.zeros(0, int)
        rel, passed = np.empty(self.count), np.empty(self.count, np.int64)
        k = _unwrap_gaps(self.s, float(ego_s), self.rel, self.was_ahead, self.track.length,
                         float(self.config.overtake_threshold), rel, passed)
        self.rel, passed = rel, passed[:k]
        for i in passed:
            self._respawn(int(i), ego_s)
        return passed

    def _respawn(self, i: int, ego_s: float) -> None:
        cfg, ep = self.config, self._episode
        ahead = cfg.respawn_distance
        others = [j for j in range(self.count) if j != i and (ep is not None or abs(self.n[j] - self.n[i]) < 2.0)]
        for _ in range(50):
            if all(abs(self.rel[j] - ahead) >= cfg.respawn_clearance for j in others):
                break
            ahead += cfg.respawn_clearance
        self.s[i] = self.track.wrap(ego_s + ahead)
        self.rel[i] = ahead
        self.was_ahead[i] = True
        self.ids[i] = self._next_id
        self._next_id += 1
        if ep is None:
            self.v[i] = self._speed(np.array([self.s[i]]))[0]
            return
        self.v[i] = ep.pace[i] * ep.lifts.factor(i, self.time) * self.track.speed(float(self.s[i]))
        self.n[i], self.n_dot[i] = self._line_start(i), 0.0
        self._squeezed[i] = False
        ep.defence.forget(i)

    # ------------------------------------------------------------------ poses
    def behaviour(self) -> np.ndarray:
        """What each opponent is doing now (for display): 0 racing on its line, 1 defending (a defensive
        move toward the ego's line, or holding it), 2 lifting (below its pace). All 0 with the
        behaviours off."""
        out = np.zeros(self.count, dtype=int)
        ep = self._episode
        if ep is None:
            return out
        for i in range(self.count):
            if ep.defence.mode[i] != IDLE:
                out[i] = 1
            elif ep.lifts.factor(i, self.time) < 1.0:
                out[i] = 2
        return out

    def poses(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Cartesian position and yaw of every opponent: (x, y, psi).

        The yaw is the raceline heading plus the heading of the lateral motion,
        ``atan2(n_dot, (1 - kappa n) v)`` (exactly the raceline heading when ``n_dot`` is 0).
        Cached for an unchanged state, since the world asks several times per step; the
        returned arrays must not be modified.
        """
        key = self.s.tobytes() + self.n.tobytes() + self.n_dot.tobytes() + self.v.tobytes()
        if self._pose_cache is not None and self._pose_cache[0] == key:
            return self._pose_cache[1]
        x, y, psi = self.track.poses(self.s, self.n)  # Track.pose of each car
        if any(self.n_dot.tolist()):  # some n_dot != 0 (or nan)
            moving = self.n_dot != 0.0
            kappa = np.asarray(self.track.curvature(self.s[moving]), float)
            along = np.maximum((1.0 - kappa * self.n[moving]) * self.v[moving], 1e-3)
            psi[moving] += np.arctan2(self.n_dot[moving], along)
        for a in (x, y, psi):
            a.setflags(write=False)
        self._pose_cache = (key, (x, y, psi))
        return x, y, psi


# compiled loops of the field's per-step updates (one call instead of a dozen scalar track calls or
# numpy calls on a few elements; the same operations in the same order: see sofar_env._jit)
@kernel
def _advance_on_profile(s, rho, dt, length, knots, table, s_new, v_new):
    """Into ``s_new``, ``v_new``: the arc lengths and speeds of cars at ``s`` [m] driving ``rho`` times the speed
    profile ``table`` for ``dt`` [s] by the midpoint rule, ``s + dt rho v(s + dt/2 rho v(s))`` wrapped into
    [0, L), and ``rho v`` there, with the track's scalar interpolation (``Track.speed`` at a float)."""
    for i in range(s.shape[0]):
        v0 = rho * lerp_wrapped(s[i], length, knots, table)
        r = floor_mod(s[i] + dt * rho * lerp_wrapped(s[i] + 0.5 * dt * v0, length, knots, table), length)
        if r >= length:
            r = 0.0
        s_new[i] = r
        v_new[i] = rho * lerp_wrapped(r, length, knots, table)


@kernel
def _unwrap_gaps(s, ego_s, rel, was_ahead, length, threshold, new, passed):
    """Into ``new``: the unwrapped gaps to the ego after a step, each old gap ``rel`` [m] plus the change of the
    periodic gap ``Track.gap(s, ego_s)``, itself wrapped into [-L/2, L/2). Sets ``was_ahead`` (in place)
    where the new gap is > 0, and puts into ``passed`` the indices of the cars that were ahead and are now
    ``threshold`` [m] or more behind; returns how many."""
    half = 0.5 * length
    k = 0
    for i in range(s.shape[0]):
        r = floor_mod(s[i] - ego_s + half, length)
        if r >= length:
            r = 0.0
        new[i] = rel[i] + (floor_mod((r - half) - rel[i] + half, length) - half)
        if new[i] > 0.0:
            was_ahead[i] = True
        if was_ahead[i] and new[i] <= -threshold:
            passed[k] = i
            k += 1
    return k


@kernel
def _advance_along(field, t, dt, pace_model, traffic, band_envelope, out):
    """Into ``out = (s_new, v_new)``: the along-track step of an interactive field (``field``: ``(s, n, v, gap,
    squeezed)``) from ``t`` over ``dt`` [s]. Each car drives its pace times its lift factor
    (:func:`~.pace.lift_factor_at` at ``t - lift_start``) times the speed profile for ``dt`` by the midpoint rule
    (``pace_model``: ``(pace, lift_start, lift_duration, lift_ramp, lift_depth, knots, table)``); the traffic rules
    then limit the advances (:func:`~.traffic.limit_advances_at`; ``traffic``: ``(follow, band_width,
    alongside)``; ``band_envelope``: :meth:`~.lateral.EdgeBand.envelope_data`); the new speed is the pace at the
    new arc length, at most the advance over ``dt`` for a limited car. The track's scalar interpolation and wrap
    (``Track.speed``, ``Track.wrap`` at a float)."""
    s, n, v, gap, squeezed = field
    pace, lift_start, lift_duration, lift_ramp, lift_depth, knots, table = pace_model
    follow, band_width, alongside = traffic
    soft_knots, soft_lo, soft_hi, _, _, length = band_envelope
    s_new, v_new = out
    m = s.shape[0]
    ds = np.empty(m)
    for i in range(m):
        t_mid = t + 0.5 * dt
        v0 = pace[i] * lift_factor_at(t - lift_start[i], lift_duration, lift_ramp, lift_depth) * lerp_wrapped(
            s[i], length, knots, table)
        x = floor_mod(s[i] + 0.5 * dt * v0, length)
        x = 0.0 if x >= length else x
        v_mid = pace[i] * lift_factor_at(t_mid - lift_start[i], lift_duration, lift_ramp, lift_depth) * lerp_wrapped(
            x, length, knots, table)
        ds[i] = dt * v_mid
    capped = np.zeros(m, dtype=np.bool_)
    limit_advances_at(ds, s, n, v, gap, dt, squeezed, follow, band_width, alongside, soft_knots, soft_lo, soft_hi,
                      length, capped)
    t_end = t + dt
    for i in range(m):
        x = floor_mod(s[i] + ds[i], length)
        s_new[i] = 0.0 if x >= length else x
        vi = pace[i] * lift_factor_at(t_end - lift_start[i], lift_duration, lift_ramp, lift_depth) * lerp_wrapped(
            s_new[i], length, knots, table)
        v_new[i] = py_min(vi, ds[i] / dt) if capped[i] else vi
