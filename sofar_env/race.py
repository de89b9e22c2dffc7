"""The race world: controlled cars, scripted opponents, events and metrics.

``Race`` is the one simulation core under the Gymnasium and PettingZoo
adapters. It holds ``n_cars`` controlled cars (the ego is car 0; the
PettingZoo environment uses several) integrated by :class:`~sofar_env.vehicle.Plant`,
plus a field of scripted :class:`~sofar_env.opponents.Opponents`. Every step it reports, per
controlled car:

* ``collision``: its footprint (an oriented ``length x width`` rectangle)
  intersects the footprint of an opponent or of another controlled car;
* ``off_track``: a corner of its footprint lies beyond an edge, i.e. the
  corner's Frenet offset exceeds ``width_left(s)`` or ``-width_right(s)`` at the
  corner's own arc length;
* ``overtakes``: in a single-car race, scripted opponents counted as overtaken
  (and respawned ahead, the paper's protocol); in a multi-car race, another
  controlled car or a scripted opponent that was ahead of this car and fell
  ``overtake_threshold`` behind it (see *Scripted opponents in a multi-car race*);
* ``progress``: arc length gained along the track [m]; laps = total progress /
  track length.

All randomness comes from the ``numpy.random.Generator`` passed to
:meth:`Race.reset`: the start arc length (uniform on the raceline) and the start
speed (uniform in ``start_speed_fraction`` x the speed profile there).

The start of a multi-car race is a rolling start from a grid two abreast and
staggered (:meth:`Race.grid_slot`): row ``r`` holds cars ``2r`` and ``2r + 1``;
its first car starts ``r x grid_row_spacing`` behind the pole (car 0, at the drawn
start arc length) and ``grid_lateral_offset`` left of the raceline, its second car
``grid_stagger`` further back and as far right; a car alone in its row (a single
car, or the last car of an odd field) starts on the raceline. A car whose offset
would bring its footprint within ``START_EDGE_MARGIN`` of an edge is moved inwards;
since the stagger is longer than a car, no two footprints overlap. Every car starts
at the drawn fraction of the speed profile at its own arc length.

**Scripted opponents in a multi-car race.** They start at their configured gaps ahead of the pole
and are never respawned: they are slower traffic that the controlled cars pass, and lap. Each
controlled car is credited once per pass of each scripted opponent (the unwrapped gap from the car
to the opponent, as between controlled cars); once the opponent is more than half a lap behind the
car it counts as ahead again, so lapping it is another pass. With the interactive behaviours on,
each opponent defends against the nearest controlled car behind it and keeps clear of every
controlled car alongside (:func:`~sofar_env.opponents.steering.steer`).
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass

import numpy as np
from scipy.ndimage import minimum_filter1d

from ._jit import kernel, minimum
from .dynamics import DynamicPlant
from .geometry import footprint_corner_list, footprint_corners, footprint_radius, rectangles_intersect
from .opponents import Opponents
from .race_config import (GRID_MIN_GAP, MAX_SPEED_FACTOR, MAX_START_SPEED_FACTOR, PLANTS,  # noqa: F401
                          START_EDGE_MARGIN, RaceConfig, _is_real)
from .vehicle import Plant, slip_angle

__all__ = ["RaceConfig", "CarEvents", "Race"]

_EDGE_WINDOW = 15.0
"""Half width of the arc-length window of the off-track prefilter [m]: a footprint corner
(within ~2.6 m of the reference point) projects within it unless 1 - kappa n < 0.2."""


@dataclass
class CarEvents:
    """What happened to one controlled car during one step."""

    collision: bool = False
    off_track: bool = False
    overtakes: int = 0
    progress: float = 0.0
    """Arc length gained [m]."""


class Race:
    """Controlled cars and scripted opponents on one track."""

    def __init__(self, track, config: RaceConfig | None = None, n_cars: int = 1):
        self.track = track
        self.config = config or RaceConfig()
        if n_cars < 1:
            raise ValueError("n_cars must be >= 1")
        self.n_cars = int(n_cars)
        self._check_grid_fits()
        self.dynamic = self.config.plant == "dynamic"
        if self.dynamic:
            self.plant = DynamicPlant(self.config.dynamic, self.config.vehicle, self.config.dt)
        else:
            self.plant = Plant(self.config.vehicle, self.config.dt, self.config.plant_substeps)
        self.plant_states = np.zeros((self.n_cars, self.plant.state_size if self.dynamic else 5))
        """Full plant state of each car (the dynamic plant has 9 states; the kinematic one is ``states``)."""
        self.mu = 1.0
        """Friction coefficient of the episode (dynamic plant) [-]."""
        self.opponents = Opponents(track, self.config.opponents, self.config.vehicle)
        self.states = np.zeros((self.n_cars, 5))
        """Cartesian state (x, y, psi, v, delta) of each controlled car."""
        self.frenet = np.zeros((self.n_cars, 5))
        """Frenet state (s, n, e, v, delta) of each controlled car."""
        self.active = np.ones(self.n_cars, bool)
        self.time = 0.0
        self.steps = 0
        self.distance = np.zeros(self.n_cars)
        self.overtakes = np.zeros(self.n_cars, int)
        self._car_rel = np.zeros((self.n_cars, self.n_cars))
        self._car_ahead = np.zeros((self.n_cars, self.n_cars), bool)
        self._opp_rel = np.zeros((self.n_cars, 0))  # multi-car races: unwrapped gap car -> scripted opponent
        self._opp_ahead = np.zeros((self.n_cars, 0), bool)
        # off-track prefilter: the smallest width within +-_EDGE_WINDOW of each raceline sample
        # (the corners' own projections are only needed near an edge)
        p = self.config.vehicle
        self._corner_reach = footprint_radius(p)
        # two footprints can only touch when their reference points are within twice that radius
        # (the 1 mm of slack keeps the prefilter exact whatever the rounding)
        self._contact_dist2 = (2.0 * self._corner_reach + 1e-3) ** 2
        samples = np.asarray(track.s, float)
        spacing = track.length / len(samples)
        half = int(math.ceil(_EDGE_WINDOW / spacing))
        self._samples = samples.tolist()
        self._wl_min = minimum_filter1d(np.asarray(track.width_left(samples), float), 2 * half + 1, mode="wrap").tolist()
        self._wr_min = minimum_filter1d(np.asarray(track.width_right(samples), float), 2 * half + 1, mode="wrap").tolist()
        self._check_opponent_field()

    def _check_grid_fits(self) -> None:
        """Raise ``ValueError`` if the last grid slot would come round the lap to the pole."""
        cfg = self.config
        row, second = divmod(self.n_cars - 1, 2)
        back = row * cfg.grid_row_spacing + second * cfg.grid_stagger
        room = self.track.length - cfg.vehicle.length - GRID_MIN_GAP
        if back >= room:
            raise ValueError(f"a grid of {self.n_cars} cars ({back:.0f} m from the pole to the last car) does not fit "
                             f"on {self.track.name} ({self.track.length:.0f} m): use fewer cars or a shorter "
                             "race.grid_row_spacing")

    def _check_opponent_field(self) -> None:
        """Raise ``ValueError`` if the configured opponent field cannot be placed on this circuit."""
        cfg = self.config.opponents
        half_width = 0.5 * self.config.vehicle.width
        wl = float(np.min(self.track.width_left(np.asarray(self.track.s, float))))
        wr = float(np.min(self.track.width_right(np.asarray(self.track.s, float))))
        for o in cfg.offsets:
            if not (o + half_width <= wl and half_width - o <= wr):
                raise ValueError(f"race.opponents.offsets: an opponent at n = {o:g} m would leave {self.track.name} "
                                 f"where it is narrowest (raceline-to-edge {wl:.2f} m left, {wr:.2f} m right, car "
                                 f"half-width {half_width:g} m): use offsets in [{half_width - wr:.2f}, "
                                 f"{wl - half_width:.2f}] m")
        self.check_opponent_count(cfg.n_opponents)

    # ------------------------------------------------------------------ reset
    def check_reset(self, *, start_s=None, start_speed=None, rho=None, n_opponents=None) -> None:
        """Raise ``ValueError`` naming the option if a :meth:`reset` with these options would be invalid.

        Nothing is changed: callers validate first, so a failed reset leaves the race as it was.
        """
        if start_s is not None and not (_is_real(start_s) and math.isfinite(start_s)):
            raise ValueError(f"start_s must be a finite number [m], got {start_s!r}")
        if start_speed is not None:
            top = MAX_START_SPEED_FACTOR * float(np.max(self.track.speed(np.asarray(self.track.s, float))))
            if not (_is_real(start_speed) and math.isfinite(start_speed) and 0.0 <= start_speed <= top):
                raise ValueError(f"start_speed must be a number in [0, {top:.1f}] m/s ({MAX_START_SPEED_FACTOR} x "
                                 f"the circuit's top profile speed), got {start_speed!r}")
        if rho is not None and not (_is_real(rho) and 0.0 <= rho <= 2.0):
            raise ValueError(f"rho must be a number in [0, 2], got {rho!r}")
        if n_opponents is not None:
            if not (_is_real(n_opponents) and float(n_opponents) == int(n_opponents) and n_opponents >= 0):
                raise ValueError(f"n_opponents must be a whole number >= 0, got {n_opponents!r}")
            self.check_opponent_count(int(n_opponents))

    def check_opponent_count(self, n: int) -> None:
        """Raise ``ValueError`` if ``n`` opponents do not fit on the lap at their spawn gaps."""
        if n == 0:
            return
        cfg = self.config.opponents
        furthest = cfg.gap(n - 1)
        room = self.track.length - self.config.opponents.respawn_clearance - self._grid_back(self.n_cars - 1)
        if furthest >= room:
            raise ValueError(f"n_opponents = {n} does not fit on {self.track.name}: the last opponent would spawn "
                             f"{furthest:.0f} m ahead, beyond the lap ({self.track.length:.0f} m) less "
                             f"{cfg.respawn_clearance:g} m; at most {self.max_opponents()} fit")

    def max_opponents(self) -> int:
        """The largest opponent count whose spawn gaps fit on the lap."""
        cfg = self.config.opponents
        room = self.track.length - cfg.respawn_clearance - self._grid_back(self.n_cars - 1)
        n = 0
        while cfg.gap(n) < room and n < 10_000:
            n += 1
        return n

    def reset(self, rng: np.random.Generator, *, start_s: float | None = None, start_speed: float | None = None,
              rho: float | None = None, n_opponents: int | None = None) -> None:
        """Start a new race. Draws the start from ``rng`` unless given explicitly."""
        cfg = self.config
        L = self.track.length
        if start_s is None:
            start_s = float(rng.uniform(0.0, L)) if cfg.random_start else cfg.start_s
        start_s = float(self.track.wrap(start_s))
        frac = float(rng.uniform(*cfg.start_speed_fraction))
        self.time = 0.0
        self.steps = 0
        self.active[:] = True
        self.distance[:] = 0.0
        self.overtakes[:] = 0
        for k in range(self.n_cars):
            s_k, n_k = self.grid_slot(start_s, k)
            v_k = float(start_speed) if start_speed is not None else frac * float(self.track.speed(s_k))
            if not math.isfinite(v_k) or v_k < 0:
                raise ValueError(f"start speed must be finite and >= 0, got {v_k}")
            x, y = self.track.to_cartesian(s_k, n_k)
            psi = float(self.track.heading(s_k))
            self.states[k] = (float(x), float(y), psi, v_k, 0.0)
            self.frenet[k] = (s_k, n_k, 0.0, v_k, 0.0)
            if self.dynamic:
                self.plant_states[k] = self.plant.initial_state(float(x), float(y), psi, v_k, 0.0)
        if self.dynamic:  # drawn only in this world: the paper world's random stream is unchanged
            self.mu = float(rng.uniform(*self.config.dynamic.mu_range))
        self.opponents.reset(self.frenet[0, 0], rho=rho, n_opponents=n_opponents,
                             rng=rng if self.config.opponents.interactive else None)
        if self.n_cars > 1:  # gap from each car to each opponent, unwrapped: the pole's gap plus the car's place
            back = np.array([self._grid_back(k) for k in range(self.n_cars)])
            self._opp_rel = np.asarray(self.opponents.rel, float)[None, :] + back[:, None]
            self._opp_ahead = self._opp_rel > 0.0
        gaps = self.track.gap(self.frenet[None, :, 0], self.frenet[:, None, 0])  # [i, j] = s_j - s_i
        self._car_rel = np.asarray(gaps, float).reshape(self.n_cars, self.n_cars)
        self._car_ahead = self._car_rel > 0.0

    def _grid_back(self, car: int) -> float:
        """How far [m] car ``car`` starts behind the pole, along the track (0 for the pole)."""
        row, second = divmod(int(car), 2)
        return row * self.config.grid_row_spacing + second * self.config.grid_stagger

    def grid_slot(self, start_s: float, car: int) -> tuple[float, float]:
        """Start arc length and lateral offset (s, n) [m] of car ``car`` when the pole is at ``start_s``.

        See the module docstring: rows of two, staggered, the first car of a row on the left. Where
        one side of a row has too little room, the row moves sideways as a whole, so its two cars
        stay ``2 grid_lateral_offset`` apart as far as the track width allows.
        """
        cfg = self.config
        row, second = divmod(int(car), 2)
        front = start_s - row * cfg.grid_row_spacing
        s = float(self.track.wrap(front - second * cfg.grid_stagger))
        if second == 0 and car == self.n_cars - 1:  # alone in its row: on the raceline
            return s, 0.0
        a = float(cfg.grid_lateral_offset)
        lo1, hi1 = self._start_room(float(self.track.wrap(front)))
        lo2, hi2 = self._start_room(float(self.track.wrap(front - cfg.grid_stagger)))
        lo, hi = max(lo1, lo2), min(hi1, hi2)  # the room both cars of the row have
        centre = min(max(0.0, lo + a), hi - a) if hi - lo >= 2.0 * a else 0.5 * (lo + hi)
        lo_k, hi_k = (lo2, hi2) if second else (lo1, hi1)
        return s, min(max(centre + (-a if second else a), lo_k), hi_k)

    def _start_room(self, s: float) -> tuple[float, float]:
        """Lateral offsets [lo, hi] [m] a controlled car may start at, at arc length ``s``.

        The footprint (aligned with the raceline) keeps ``START_EDGE_MARGIN`` from the narrowest edge
        within +-15 m of ``s``, so no car starts off the track, whatever the start arc length; the
        raceline (0) is always inside.
        """
        i = bisect.bisect_right(self._samples, s) - 1
        half = 0.5 * self.config.vehicle.width + START_EDGE_MARGIN
        return min(half - self._wr_min[i], 0.0), max(self._wl_min[i] - half, 0.0)

    # ------------------------------------------------------------------ queries
    def opponent_frenet(self, car: int = 0) -> np.ndarray:
        """Rows (s, n, v) of everything car ``car`` must avoid: scripted opponents and other active cars.

        ``s`` is absolute arc length [m], ``v`` the arc-length speed ds/dt [m/s].
        """
        rows = []
        if self.opponents.count:
            opp = np.empty((self.opponents.count, 3))  # np.column_stack of (s, n, v), without its checks
            opp[:, 0], opp[:, 1], opp[:, 2] = self.opponents.s, self.opponents.n, self.opponents.v
            rows.append(opp)
        others = [j for j in range(self.n_cars) if j != car and self.active[j]]
        if others:
            f = self.frenet[others]
            kappa = np.asarray(self.track.curvature(f[:, 0]), float)
            s_dot = f[:, 3] * np.cos(f[:, 2]) / (1.0 - kappa * f[:, 1])
            rows.append(np.column_stack([f[:, 0], f[:, 1], s_dot]))
        if len(rows) == 1:
            return rows[0]
        return np.concatenate(rows) if rows else np.zeros((0, 3))

    def opponent_lateral_rates(self, car: int = 0) -> np.ndarray:
        """Lateral rates n_dot [m/s] of the rows of :meth:`opponent_frenet`: each scripted opponent's, and
        ``v sin(e + beta)`` of each other active car (its Frenet kinematics, beta its side-slip angle)."""
        rates = [np.asarray(self.opponents.n_dot, float)] if self.opponents.count else []
        others = [j for j in range(self.n_cars) if j != car and self.active[j]]
        if others:
            p = self.config.vehicle
            rates.append(np.array([v * math.sin(e + slip_angle(d, p)) for _, _, e, v, d in
                                   self.frenet[others].tolist()]))
        return np.concatenate(rates) if rates else np.zeros(0)

    def opponent_ids(self, car: int = 0) -> np.ndarray:
        """Stable identities of the rows of :meth:`opponent_frenet` (scripted opponents >= 0, whose id
        changes at a respawn; controlled car j: -1 - j)."""
        ids = [np.asarray(self.opponents.ids, int)] if self.opponents.count else []
        others = [j for j in range(self.n_cars) if j != car and self.active[j]]
        if others:
            ids.append(-1 - np.asarray(others, int))
        return np.concatenate(ids) if ids else np.zeros(0, int)

    def obstacle_poses(self, car: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Reference-point positions and yaws (x, y, psi) of everything car ``car`` can collide with."""
        x, y, psi = self.opponents.poses()
        if self.n_cars == 1:
            return x, y, psi
        others = [j for j in range(self.n_cars) if j != car and self.active[j]]
        if others:
            st = self.states[others]
            x, y, psi = np.concatenate([x, st[:, 0]]), np.concatenate([y, st[:, 1]]), np.concatenate([psi, st[:, 2]])
        return x, y, psi

    def obstacle_corners(self, car: int = 0) -> np.ndarray:
        """Footprint corners (m, 4, 2) of everything car ``car`` can collide with."""
        x, y, psi = self.obstacle_poses(car)
        return footprint_corners(x, y, psi, self.config.vehicle)

    def nearest_distance(self, car: int = 0) -> float:
        """Distance between the reference points of car ``car`` and the nearest obstacle [m]; inf if none."""
        x, y, _ = self.obstacle_poses(car)
        xk, yk = self.states[car, :2].tolist()
        return _nearest(x, y, xk, yk)

    def laps(self, car: int = 0) -> float:
        """Completed laps of car ``car``: arc length driven / track length."""
        return float(self.distance[car] / self.track.length)

    @property
    def truncated(self) -> bool:
        return self.steps >= self.config.max_steps

    # ------------------------------------------------------------------ step
    def step(self, controls) -> list[CarEvents]:
        """Advance the world by one control period with ``controls`` (n_cars, 2) = (a, delta_dot).

        Inactive cars (crashed in a multi-car race) are left where they were and removed
        from the obstacle lists. Returns the events of every car (all False for inactive ones).
        """
        u = np.asarray(controls, float).reshape(self.n_cars, 2)
        active = [k for k, on in enumerate(self.active.tolist()) if on]
        rows = u.tolist()
        if not all(math.isfinite(a) and math.isfinite(dd) for a, dd in (rows[k] for k in active)):
            raise ValueError(f"non-finite control {rows}")
        dt = self.config.dt
        if self.dynamic:
            for k in active:
                self.plant_states[k] = self.plant.step(self.plant_states[k], u[k], self.mu)
                self.states[k] = self.plant.kinematic_view(self.plant_states[k])
        else:
            for k in active:
                self.states[k] = self.plant.step(self.states[k].tolist(), rows[k])
        if self.opponents.episode is not None:  # interactive: the controlled cars at the start of the step
            self.opponents.advance(dt, self._ego_row(0) if self.n_cars == 1 else [self._ego_row(k) for k in active])
        else:
            self.opponents.advance(dt)
        self.time += dt
        self.steps += 1
        events = [CarEvents() for _ in range(self.n_cars)]
        track = self.track
        for k in active:
            s_old = self.frenet[k, 0].item()
            x, y, psi, v, delta = self.states[k].tolist()
            s, n = track.to_frenet(x, y, s_hint=s_old)
            s, n = float(s), float(n)
            e = (psi - track.heading(s) + math.pi) % (2.0 * math.pi) - math.pi
            self.frenet[k] = (s, n, e, v, delta)
            ev = events[k]
            ev.progress = float(track.gap(s, s_old))
            self.distance[k] += ev.progress
            ev.off_track = self._off_track(k)
            ev.collision = self._collides(k)
        if self.n_cars == 1:
            passed = self.opponents.update_overtakes(self.frenet[0, 0])
            events[0].overtakes = int(passed.size)
        else:
            self._update_car_overtakes(events)
            if self.opponents.count:
                self._update_opponent_overtakes(events)
        for k in range(self.n_cars):
            self.overtakes[k] += events[k].overtakes
        return events

    def _ego_row(self, car: int) -> tuple[float, float, float]:
        """(s, n, arc-length speed) of controlled car ``car``, as the opponents' behaviours see it."""
        s0, n0, e0, v0, _ = self.frenet[car].tolist()
        return s0, n0, v0 * math.cos(e0) / (1.0 - float(self.track.curvature(s0)) * n0)

    def deactivate(self, car: int) -> None:
        """Remove a car from the race (it no longer moves or counts as an obstacle)."""
        self.active[car] = False

    # ------------------------------------------------------------------ events
    def _off_track(self, k: int) -> bool:
        s_c, n_c = float(self.frenet[k, 0]), float(self.frenet[k, 1])
        i = bisect.bisect_right(self._samples, s_c) - 1
        reach = self._corner_reach
        # every corner lies within `reach` of the reference point, so its offset is within
        # n +- reach and its projection within _EDGE_WINDOW of s: inside both minimum widths
        # over the window, no corner can be beyond an edge
        if n_c + reach < self._wl_min[i] and reach - n_c < self._wr_min[i]:
            return False
        x, y, psi = self.states[k, :3].tolist()
        track = self.track
        # one scalar projection per corner, seeded at the car's own s (the track's scalar path is the fast one)
        for cx, cy in footprint_corner_list(x, y, psi, self.config.vehicle):
            s, n = track.to_frenet(cx, cy, s_hint=s_c)
            if n > track.width_left(s) or n < -track.width_right(s):
                return True
        return False

    def _collides(self, k: int) -> bool:
        x, y, psi = self.obstacle_poses(k)
        if x.size == 0:
            return False
        # bounding-circle prefilter: only cars whose reference points are within 2 footprint radii can touch
        xk, yk = self.states[k, :2].tolist()
        near = np.empty(x.shape[0], bool)
        if not _within(x, y, xk, yk, self._contact_dist2, near):
            return False
        p = self.config.vehicle
        obstacles = footprint_corners(x[near], y[near], psi[near], p)
        ego = footprint_corners(self.states[k, 0], self.states[k, 1], self.states[k, 2], p)
        return bool(np.any(rectangles_intersect(ego[None], obstacles)))

    def _update_car_overtakes(self, events: list[CarEvents]) -> None:
        L = self.track.length
        s = self.frenet[:, 0]
        gaps = np.asarray(self.track.gap(s[None, :], s[:, None]), float)
        _unwrap(self._car_rel, gaps, L)
        self._car_ahead |= self._car_rel > 0.0
        thr = self.config.opponents.overtake_threshold
        for i in np.flatnonzero(self.active):
            for j in np.flatnonzero(self.active):
                if i != j and self._car_ahead[i, j] and self._car_rel[i, j] <= -thr:
                    events[i].overtakes += 1
                    self._car_ahead[i, j] = False

    def _update_opponent_overtakes(self, events: list[CarEvents]) -> None:
        """Credit each active car with the scripted opponents it passed in this step (multi-car races)."""
        L = self.track.length
        gaps = np.asarray(self.track.gap(self.opponents.s[None, :], self.frenet[:, 0][:, None]), float)
        _unwrap(self._opp_rel, gaps, L)
        lapped = self._opp_rel < -0.5 * L  # more than half a lap behind: ahead again, to be lapped
        self._opp_rel[lapped] += L
        lapping = self._opp_rel > 0.5 * L  # a faster opponent more than half a lap ahead: behind again
        self._opp_rel[lapping] -= L
        self._opp_ahead[lapping] = False
        self._opp_ahead |= self._opp_rel > 0.0
        thr = self.config.opponents.overtake_threshold
        for i in np.flatnonzero(self.active):
            passed = self._opp_ahead[i] & (self._opp_rel[i] <= -thr)
            events[i].overtakes += int(passed.sum())
            self._opp_ahead[i, passed] = False


def _unwrap(rel: np.ndarray, gaps: np.ndarray, length: float) -> None:
    """Advance the unwrapped gaps ``rel`` in place to the periodic ``gaps`` of this step (a step moves
    every gap by less than half a lap)."""
    rel += (gaps - rel + 0.5 * length) % length - 0.5 * length


@kernel
def _nearest(x, y, xk, yk):
    """Smallest ``np.hypot(x - xk, y - yk)`` [m] over the points (x, y) (``np.min``'s reduction, a nan
    propagates); inf if there are none. Compiled: one call instead of five numpy calls on a few points."""
    best = np.inf
    for i in range(x.shape[0]):
        best = minimum(best, np.hypot(x[i] - xk, y[i] - yk))
    return best


@kernel
def _within(x, y, xk, yk, reach2, near):
    """Sets ``near`` where the squared distance of the point (x, y) to (xk, yk) is below ``reach2`` [m^2];
    whether any is (the bounding-circle prefilter of the collision test, compiled). Its squares are products
    (a Python ``** 2`` may differ by an ulp): the 1 mm of slack in ``reach2`` keeps the test exact."""
    found = False
    for i in range(x.shape[0]):
        dx, dy = x[i] - xk, y[i] - yk
        near[i] = dx * dx + dy * dy < reach2
        found = found or near[i]
    return found
