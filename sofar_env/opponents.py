"""Scripted opponent cars: raceline followers at a pace ratio, respawned once overtaken.

Each opponent drives along the raceline at a constant lateral offset ``n`` [m]
with arc-length speed ``ds/dt = rho * v_profile(s)`` [m/s], where ``v_profile``
is the circuit's speed profile and ``rho`` the pace ratio of the paper. Opponents
ignore the ego and each other.

Overtakes. For every opponent the signed gap to the ego, ``s_opp - s_ego`` [m],
is tracked *unwrapped* (increments of the periodic gap are accumulated), so a
car that falls half a lap behind is never mistaken for one just passed. An
opponent that has been ahead (gap > 0) and then falls ``overtake_threshold``
behind is counted once and respawned ``respawn_distance`` ahead of the ego (the
spot is moved further ahead while it would overlap another opponent on the
same side).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["OpponentConfig", "Opponents"]


@dataclass(frozen=True)
class OpponentConfig:
    """Opponent field. ``offsets`` are cycled to ``n_opponents`` entries, ``gaps`` repeated further ahead."""

    n_opponents: int = 4
    """Number of opponent cars."""
    offsets: tuple[float, ...] = (0.0, 1.0, -1.0, 0.0)
    """Lateral offset of each opponent from the raceline [m], + left."""
    rho: float = 0.3
    """Pace ratio: opponent speed / speed profile [-]."""
    gaps: tuple[float, ...] = (120.0, 180.0, 250.0, 400.0)
    """Arc-length gap of each opponent ahead of the ego at spawn [m]. With more opponents than
    entries the list repeats further ahead, each repetition shifted by its largest entry
    (8 opponents: 120, 180, 250, 400, 520, 580, 650, 800 m), so no two cars spawn on the same spot."""
    overtake_threshold: float = 2.0
    """An opponent counts as overtaken once it is this far behind the ego [m]."""
    respawn_distance: float = 400.0
    """An overtaken opponent reappears this far ahead of the ego [m]."""
    respawn_clearance: float = 15.0
    """Minimum arc-length spacing to another opponent on the same side at respawn [m]."""

    def __post_init__(self) -> None:
        if self.n_opponents < 0:
            raise ValueError("n_opponents must be >= 0")
        if self.n_opponents > 0 and (len(self.offsets) == 0 or len(self.gaps) == 0):
            raise ValueError("offsets and gaps need at least one entry")
        if not (0.0 <= self.rho <= 2.0):
            raise ValueError(f"rho must lie in [0, 2], got {self.rho}")
        if self.n_opponents > len(self.gaps) and not max(self.gaps) > 0.0:
            raise ValueError("with more opponents than gaps, the largest gap must be > 0 (the list repeats "
                             "shifted by it)")
        if self.overtake_threshold <= 0 or self.respawn_distance <= 0:
            raise ValueError("overtake_threshold and respawn_distance must be positive")

    def offset(self, i: int) -> float:
        return float(self.offsets[i % len(self.offsets)])

    def gap(self, i: int) -> float:
        k = len(self.gaps)
        return float(self.gaps[i % k]) + (i // k) * max(self.gaps)


@dataclass
class Opponents:
    """State of the opponent field on one track (arrays of length ``n``)."""

    track: object
    config: OpponentConfig
    s: np.ndarray = field(default_factory=lambda: np.zeros(0))
    """Arc length [m] in [0, L)."""
    n: np.ndarray = field(default_factory=lambda: np.zeros(0))
    """Lateral offset [m]."""
    v: np.ndarray = field(default_factory=lambda: np.zeros(0))
    """Arc-length speed ds/dt [m/s]."""
    rel: np.ndarray = field(default_factory=lambda: np.zeros(0))
    """Unwrapped gap to the ego, s_opp - s_ego [m] (> 0 ahead)."""
    was_ahead: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    rho: float = 0.0
    _pose_cache: tuple | None = field(default=None, init=False, repr=False, compare=False)

    @property
    def count(self) -> int:
        return int(self.s.shape[0])

    def reset(self, ego_s: float, rho: float | None = None, n_opponents: int | None = None) -> None:
        """Place the opponents at their configured gaps ahead of the ego."""
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
        self.v = self._speed(self.s)

    def _speed(self, s: np.ndarray) -> np.ndarray:
        if s.size == 0:
            return np.zeros(0)
        return self.rho * np.asarray(self.track.speed(s), float)

    def advance(self, dt: float) -> None:
        """Move every opponent ``dt`` [s] along the raceline (midpoint speed rule)."""
        if self.count == 0:
            return
        track, rho = self.track, self.rho
        # a scalar loop: for a handful of cars the track's scalar paths beat its array paths
        s_new = []
        for s in self.s.tolist():
            v0 = rho * track.speed(s)
            s_new.append(track.wrap(s + dt * rho * track.speed(s + 0.5 * dt * v0)))
        self.s = np.array(s_new)
        self.v = np.array([rho * track.speed(s) for s in s_new])

    def update_overtakes(self, ego_s: float) -> np.ndarray:
        """Update the gaps after a step; count and respawn overtaken opponents.

        Returns the indices of the opponents overtaken in this step.
        """
        if self.count == 0:
            return np.zeros(0, int)
        gap = np.asarray(self.track.gap(self.s, ego_s), float)
        # unwrap: the change of the periodic gap is small between two steps
        L = self.track.length
        delta = (gap - self.rel + 0.5 * L) % L - 0.5 * L
        self.rel = self.rel + delta
        self.was_ahead |= self.rel > 0.0
        passed = (self.was_ahead & (self.rel <= -self.config.overtake_threshold)).nonzero()[0]
        for i in passed:
            self._respawn(int(i), ego_s)
        return passed

    def _respawn(self, i: int, ego_s: float) -> None:
        cfg = self.config
        ahead = cfg.respawn_distance
        others = [j for j in range(self.count) if j != i and abs(self.n[j] - self.n[i]) < 2.0]
        for _ in range(50):
            if all(abs(self.rel[j] - ahead) >= cfg.respawn_clearance for j in others):
                break
            ahead += cfg.respawn_clearance
        self.s[i] = self.track.wrap(ego_s + ahead)
        self.rel[i] = ahead
        self.was_ahead[i] = True
        self.v[i] = self._speed(np.array([self.s[i]]))[0]

    def poses(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Cartesian position and yaw of every opponent: (x, y, psi).

        Cached for unchanged (s, n), since the world asks several times per step; the
        returned arrays must not be modified.
        """
        key = self.s.tobytes() + self.n.tobytes()
        if self._pose_cache is not None and self._pose_cache[0] == key:
            return self._pose_cache[1]
        pose = self.track.pose
        # a scalar loop: the field is small and the track's scalar paths are ~30x faster than its array paths
        rows = [pose(s, n) for s, n in zip(self.s.tolist(), self.n.tolist())]
        x, y, psi = (np.array(col, dtype=float) for col in zip(*rows)) if rows else (np.zeros(0) for _ in range(3))
        for a in (x, y, psi):
            a.setflags(write=False)
        self._pose_cache = (key, (x, y, psi))
        return x, y, psi
