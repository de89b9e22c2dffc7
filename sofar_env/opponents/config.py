"""Configuration of the opponent field: where the cars start and how they drive.

:class:`OpponentConfig` holds the paper's field (count, lateral offsets, pace
ratio, spawn gaps, overtake and respawn rules) and four groups of behaviours,
all off by default so that the default field is the paper's:

* :class:`PaceConfig`: a pace ratio per car drawn around ``rho``, and lifts
  (a car briefly slows down and speeds up again, at random times);
* :class:`LineConfig`: each car drives its own slowly changing line around its
  lateral offset instead of a fixed offset;
* :class:`DefenceConfig`: a car defends against the ego closing from behind with
  one blocking move per approach, following the etiquette of racing (no move
  once the attacker is alongside, never steering into it);
* :class:`TrafficConfig`: how opponents keep clear of each other (always used
  when any behaviour is on: with equal paces and fixed offsets, as in the paper,
  cars never close on each other).

The numbers follow the opponent models of racing research: the reactive blocking
opponents of the game-racer project (wulemao/game-racer) vary a speed factor on
the raceline speed in [0.85, 1.1] and a blocking weight in [0, 1], which suggests
a pace spread of 10-15 % and an aggressiveness drawn per car; the defence follows
the etiquette commonly modelled (one defensive move per approach, no move once
the attacker is alongside).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

__all__ = ["PaceConfig", "LineConfig", "DefenceConfig", "TrafficConfig", "OpponentConfig"]


def _check(condition: bool, message: str) -> None:
    if not condition:
        raise ValueError(message)


def _finite(*values: float) -> bool:
    return all(math.isfinite(v) for v in values)


@dataclass(frozen=True)
class PaceConfig:
    """Per-car pace ratios and lifts. Off with ``spread = 0`` and ``lift_rate = 0``."""

    spread: float = 0.0
    """Each car's pace ratio is ``rho * U(1 - spread, 1 + spread)``, drawn per episode [-], in [0, 1)."""
    lift_rate: float = 0.0
    """Rate of the Poisson process of lifts of each car [1/s], >= 0 (0: no lifts). One lift at a time."""
    lift_depth: float = 0.8
    """Pace during a lift, as a fraction of the car's pace [-], in (0, 1]."""
    lift_duration: float = 4.0
    """Duration of a lift, ramps included [s], > 0."""
    lift_ramp: float = 1.5
    """Duration of the (raised-cosine) ramp down at the start and up at the end of a lift [s], in
    (0, lift_duration / 2]. The speed is continuous and the deceleration at most
    pi (1 - depth) v / (2 ramp): 0.1 g at 60 m/s with the defaults."""

    def __post_init__(self) -> None:
        _check(_finite(self.spread, self.lift_rate, self.lift_depth, self.lift_duration, self.lift_ramp),
               "pace settings must be finite")
        _check(0.0 <= self.spread < 1.0, f"pace.spread must lie in [0, 1), got {self.spread}")
        _check(self.lift_rate >= 0.0, f"pace.lift_rate must be >= 0, got {self.lift_rate}")
        _check(0.0 < self.lift_depth <= 1.0, f"pace.lift_depth must lie in (0, 1], got {self.lift_depth}")
        _check(self.lift_duration > 0.0, "pace.lift_duration must be positive")
        _check(0.0 < self.lift_ramp <= 0.5 * self.lift_duration,
               f"pace.lift_ramp must lie in (0, lift_duration / 2], got {self.lift_ramp}")

    @property
    def active(self) -> bool:
        return self.spread > 0.0 or (self.lift_rate > 0.0 and self.lift_depth < 1.0)


@dataclass(frozen=True)
class LineConfig:
    """Own lines: ``n(s) = offset + A (w sin(2 pi k1 s / L + p1) + (1 - w) sin(2 pi k2 s / L + p2))``.

    ``A ~ U(0.5, 1) amplitude``, ``w ~ U(0.3, 0.7)``, phases uniform, and the wave numbers ``k1 != k2``
    integers with wavelengths ``L / k`` in ``wavelengths`` (so a line is a fixed curve of the lap),
    all drawn per car and episode. Off with ``amplitude = 0``. The line is a target: the car
    follows it with bounded lateral speed and acceleration, inside the edges.
    """

    amplitude: float = 0.0
    """Largest deviation of a line from the car's lateral offset [m], >= 0 (0: fixed offsets)."""
    wavelengths: tuple[float, float] = (300.0, 900.0)
    """Range of the wavelengths of the two sinusoids [m]."""
    lateral_speed: float = 1.0
    """Bound on the lateral speed |dn/dt| while following the line [m/s], > 0."""
    lateral_accel: float = 1.0
    """Bound on the lateral acceleration |d2n/dt2| while following the line [m/s^2], > 0."""
    edge_margin: float = 0.5
    """A line keeps the footprint this far inside the edges (beyond half the car width) [m], >= 0."""

    def __post_init__(self) -> None:
        lo, hi = self.wavelengths
        _check(_finite(self.amplitude, lo, hi, self.lateral_speed, self.lateral_accel, self.edge_margin),
               "line settings must be finite")
        _check(self.amplitude >= 0.0, f"lines.amplitude must be >= 0, got {self.amplitude}")
        _check(0.0 < lo <= hi, f"lines.wavelengths must be an ordered pair of positive lengths, got {self.wavelengths}")
        _check(self.lateral_speed > 0.0 and self.lateral_accel > 0.0,
               "lines.lateral_speed and lines.lateral_accel must be positive")
        _check(self.edge_margin >= 0.0, "lines.edge_margin must be >= 0")

    @property
    def active(self) -> bool:
        return self.amplitude > 0.0


@dataclass(frozen=True)
class DefenceConfig:
    """Defending against the ego. Off with ``enabled = False``.

    An *approach* starts when the ego enters the window ``min_gap <= s_car - s_ego <= max_gap``
    behind the car and ends when it falls back beyond ``max_gap + release`` or has passed. During
    an approach a car may make at most one move: once the ego is closing (at least ``min_closing``
    faster) and ``trigger`` or more to one side, it steers toward the ego's lateral offset of that
    moment and holds it. It makes no move, and stops a move, once the ego is alongside
    (``|gap| < car length + alongside_margin``). Whenever the ego is alongside or about to be
    (within ``guard_time`` at the closing speed), no lateral motion of the car brings the two
    footprints closer than ``clearance`` side to side (it never steers into the ego). This last
    rule (with ``alongside_margin``, ``clearance`` and ``guard_time``) bounds every lateral
    motion, line following included, whenever any behaviour is on and the world passes the ego.
    """

    enabled: bool = False
    """Cars defend."""
    never_defend: float = 0.25
    """Probability that a car never defends (per car and episode) [-], in [0, 1]."""
    aggressiveness: tuple[float, float] = (0.3, 1.0)
    """Range of the aggressiveness of a defending car, drawn uniformly per car and episode [-], in (0, 1].
    It scales the lateral speed of its move."""
    min_gap: float = 5.0
    """Nearest ego (behind the car) that starts a move [m], >= 0."""
    max_gap: float = 60.0
    """Farthest ego (behind the car) that starts a move [m], > min_gap."""
    release: float = 5.0
    """The approach ends when the ego falls back beyond max_gap + release [m] (hysteresis), >= 0."""
    min_closing: float = 0.5
    """The ego must be this much faster than the car (arc-length speeds) for a move [m/s], >= 0."""
    trigger: float = 0.5
    """The ego must be this far to one side of the car for a move [m], >= 0."""
    lateral_speed: float = 1.5
    """Bound on the lateral speed of a move at aggressiveness 1 [m/s], > 0."""
    lateral_accel: float = 3.0
    """Bound on the lateral acceleration of a move [m/s^2], > 0."""
    alongside_margin: float = 1.0
    """The ego is alongside when |gap| < car length + this [m], >= 0."""
    clearance: float = 1.0
    """Side-to-side clearance to the ego the car never reduces below while alongside [m], >= 0."""
    guard_time: float = 1.0
    """The clearance rule starts this long before the ego is alongside, at the closing speed [s], >= 0."""

    def __post_init__(self) -> None:
        a_lo, a_hi = self.aggressiveness
        values = (self.never_defend, a_lo, a_hi, self.min_gap, self.max_gap, self.release, self.min_closing,
                  self.trigger, self.lateral_speed, self.lateral_accel, self.alongside_margin, self.clearance,
                  self.guard_time)
        _check(_finite(*values), "defence settings must be finite")
        _check(0.0 <= self.never_defend <= 1.0, f"defence.never_defend must lie in [0, 1], got {self.never_defend}")
        _check(0.0 < a_lo <= a_hi <= 1.0, f"defence.aggressiveness must be an ordered pair in (0, 1], got "
                                          f"{self.aggressiveness}")
        _check(0.0 <= self.min_gap < self.max_gap, "defence needs 0 <= min_gap < max_gap")
        _check(min(self.release, self.min_closing, self.trigger, self.alongside_margin, self.clearance,
                   self.guard_time) >= 0.0, "defence margins, thresholds and times must be >= 0")
        _check(self.lateral_speed > 0.0 and self.lateral_accel > 0.0,
               "defence.lateral_speed and defence.lateral_accel must be positive")

    @property
    def active(self) -> bool:
        return self.enabled and self.never_defend < 1.0


@dataclass(frozen=True)
class TrafficConfig:
    """How opponents keep clear of each other when a behaviour is on."""

    follow_gap: float = 12.0
    """A car closing on another opponent ahead in its lateral band does not close below this gap (it
    matches the other's speed) [m], > the car length."""
    side_window: float = 10.0
    """A car makes no lateral move into the band of another opponent within this arc-length distance [m], >= 0."""
    band_margin: float = 0.5
    """Two cars are in the same lateral band when their offsets differ by less than the car width plus
    this [m], >= 0."""

    def __post_init__(self) -> None:
        _check(_finite(self.follow_gap, self.side_window, self.band_margin), "traffic settings must be finite")
        _check(self.follow_gap > 0.0, "traffic.follow_gap must be positive")
        _check(self.side_window >= 0.0 and self.band_margin >= 0.0,
               "traffic.side_window and traffic.band_margin must be >= 0")


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
    pace: PaceConfig = field(default_factory=PaceConfig)
    """Per-car pace ratios and lifts (off by default)."""
    lines: LineConfig = field(default_factory=LineConfig)
    """Own lines around the offsets (off by default)."""
    defence: DefenceConfig = field(default_factory=DefenceConfig)
    """Defending against the ego (off by default)."""
    traffic: TrafficConfig = field(default_factory=TrafficConfig)
    """Keeping clear of each other (used when any behaviour is on)."""

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
        for name, cls in (("pace", PaceConfig), ("lines", LineConfig), ("defence", DefenceConfig),
                          ("traffic", TrafficConfig)):
            if not isinstance(getattr(self, name), cls):
                raise ValueError(f"{name} must be a {cls.__name__}, got {type(getattr(self, name)).__name__}")

    @property
    def interactive(self) -> bool:
        """Whether any behaviour is on (otherwise the cars move exactly as in the paper)."""
        return self.pace.active or self.lines.active or self.defence.active

    def offset(self, i: int) -> float:
        return float(self.offsets[i % len(self.offsets)])

    def gap(self, i: int) -> float:
        k = len(self.gaps)
        return float(self.gaps[i % k]) + (i // k) * max(self.gaps)
