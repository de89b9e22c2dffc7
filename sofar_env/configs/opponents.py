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

Where the numbers come from: ``docs/decisions/interactive-opponents.md``.
"""

from __future__ import annotations

from dataclasses import dataclass

from ..domains import check_fields, flag, integer, nested, neutral, real, reals
from ..errors import ConfigError

__all__ = ["PaceConfig", "LineConfig", "DefenceConfig", "TrafficConfig", "OpponentConfig"]

_PATH = "race.opponents"
"""Key path of the opponent field in an environment's configuration (named in error messages)."""


def _check(condition: bool, message: str) -> None:
    if not condition:
        raise ConfigError(message)


@dataclass(frozen=True)
class PaceConfig:
    """Per-car pace ratios and lifts. Off with ``spread = 0`` and ``lift_rate = 0``."""

    spread: float = real(0.0, ge=0.0, lt=1.0)
    """Each car's pace ratio is ``rho * U(1 - spread, 1 + spread)``, drawn per episode [-], in [0, 1)."""
    lift_rate: float = real(0.0, ge=0.0, unit="1/s")
    """Rate of the Poisson process of lifts of each car [1/s], >= 0 (0: no lifts). One lift at a time."""
    lift_depth: float = real(0.8, gt=0.0, le=1.0)
    """Pace during a lift, as a fraction of the car's pace [-], in (0, 1]."""
    lift_duration: float = real(4.0, gt=0.0, unit="s")
    """Duration of a lift, ramps included [s], > 0."""
    lift_ramp: float = real(1.5, gt=0.0, unit="s")
    """Duration of the (raised-cosine) ramp down at the start and up at the end of a lift [s], in
    (0, lift_duration / 2]. The speed is continuous and the deceleration at most
    pi (1 - depth) v / (2 ramp): 0.1 g at 60 m/s with the defaults."""

    def __post_init__(self) -> None:
        check_fields(self, f"{_PATH}.pace")
        _check(self.lift_ramp <= 0.5 * self.lift_duration,
               f"{_PATH}.pace.lift_ramp must lie in (0, lift_duration / 2], got {self.lift_ramp}")

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

    amplitude: float = real(0.0, ge=0.0, unit="m")
    """Largest deviation of a line from the car's lateral offset [m], >= 0 (0: fixed offsets)."""
    wavelengths: tuple[float, float] = reals((300.0, 900.0), size=2, gt=0.0, ordered=True, unit="m")
    """Range of the wavelengths of the two sinusoids [m]."""
    lateral_speed: float = real(1.0, gt=0.0, unit="m/s")
    """Bound on the lateral speed |dn/dt| while following the line [m/s], > 0."""
    lateral_accel: float = real(1.0, gt=0.0, unit="m/s^2")
    """Bound on the lateral acceleration |d2n/dt2| while following the line [m/s^2], > 0."""
    edge_margin: float = real(0.5, ge=0.0, unit="m")
    """A line keeps the footprint this far inside the edges (beyond half the car width) [m], >= 0."""

    def __post_init__(self) -> None:
        check_fields(self, f"{_PATH}.lines")

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

    enabled: bool = flag(False)
    """Cars defend."""
    never_defend: float = real(0.25, ge=0.0, le=1.0)
    """Probability that a car never defends (per car and episode) [-], in [0, 1]."""
    aggressiveness: tuple[float, float] = reals((0.3, 1.0), size=2, gt=0.0, le=1.0, ordered=True)
    """Range of the aggressiveness of a defending car, drawn uniformly per car and episode [-], in (0, 1].
    It scales the lateral speed of its move."""
    min_gap: float = real(5.0, ge=0.0, unit="m")
    """Nearest ego (behind the car) that starts a move [m], >= 0."""
    max_gap: float = real(60.0, gt=0.0, unit="m")
    """Farthest ego (behind the car) that starts a move [m], > min_gap."""
    release: float = real(5.0, ge=0.0, unit="m")
    """The approach ends when the ego falls back beyond max_gap + release [m] (hysteresis), >= 0."""
    min_closing: float = real(0.5, ge=0.0, unit="m/s")
    """The ego must be this much faster than the car (arc-length speeds) for a move [m/s], >= 0."""
    trigger: float = real(0.5, ge=0.0, unit="m")
    """The ego must be this far to one side of the car for a move [m], >= 0."""
    lateral_speed: float = real(1.5, gt=0.0, unit="m/s")
    """Bound on the lateral speed of a move at aggressiveness 1 [m/s], > 0."""
    lateral_accel: float = real(3.0, gt=0.0, unit="m/s^2")
    """Bound on the lateral acceleration of a move [m/s^2], > 0."""
    alongside_margin: float = real(1.0, ge=0.0, unit="m")
    """The ego is alongside when |gap| < car length + this [m], >= 0."""
    clearance: float = real(1.0, ge=0.0, unit="m")
    """Side-to-side clearance to the ego the car never reduces below while alongside [m], >= 0."""
    guard_time: float = real(1.0, ge=0.0, unit="s")
    """The clearance rule starts this long before the ego is alongside, at the closing speed [s], >= 0."""

    def __post_init__(self) -> None:
        check_fields(self, f"{_PATH}.defence")
        _check(self.min_gap < self.max_gap, f"{_PATH}.defence needs min_gap < max_gap, got {self.min_gap} and "
                                            f"{self.max_gap}")

    @property
    def active(self) -> bool:
        return self.enabled and self.never_defend < 1.0


@dataclass(frozen=True)
class TrafficConfig:
    """How opponents keep clear of each other when a behaviour is on."""

    follow_gap: float = real(12.0, gt=0.0, unit="m")
    """A car closing on another opponent ahead in its lateral band does not close below this gap (it
    matches the other's speed) [m], > the car length."""
    side_window: float = real(10.0, ge=0.0, unit="m")
    """A car makes no lateral move into the band of another opponent within this arc-length distance [m], >= 0."""
    band_margin: float = real(0.5, ge=0.0, unit="m")
    """Two cars are in the same lateral band when their offsets differ by less than the car width plus
    this [m], >= 0."""
    yield_to_any: bool = neutral(flag(True))
    """Whether a *squeezed* car (no room beside a car or ego it keeps clear of,
    :mod:`~sofar_env.opponents.steering`) brakes whoever squeezes it (True: the behaviour of every committed
    table). False: it brakes only when one of them is ahead of it (or level) or faster than it, since dropping back
    makes room only for a car that moves past; a car squeezed by a slower or standing car behind it keeps its pace.
    With True, a car squeezed by a standing ego (or opponent) a car length behind it brakes to a standstill and
    stays squeezed while both stand: a deadlock that holds the ego behind it until the stall rule ends the
    episode. Decision: ``docs/decisions/interactive-opponents.md``."""

    def __post_init__(self) -> None:
        check_fields(self, f"{_PATH}.traffic")


@dataclass(frozen=True)
class OpponentConfig:
    """Opponent field. ``offsets`` are cycled to ``n_opponents`` entries, ``gaps`` repeated further ahead."""

    n_opponents: int = integer(4, ge=0)
    """Number of opponent cars."""
    offsets: tuple[float, ...] = reals((0.0, 1.0, -1.0, 0.0), unit="m")
    """Lateral offset of each opponent from the raceline [m], + left."""
    rho: float = real(0.3, ge=0.0, le=2.0)
    """Pace ratio: opponent speed / speed profile [-]."""
    gaps: tuple[float, ...] = reals((120.0, 180.0, 250.0, 400.0), unit="m")
    """Arc-length gap of each opponent ahead of the ego at spawn [m]. With more opponents than
    entries the list repeats further ahead, each repetition shifted by its largest entry
    (8 opponents: 120, 180, 250, 400, 520, 580, 650, 800 m), so no two cars spawn on the same spot."""
    overtake_threshold: float = real(2.0, gt=0.0, unit="m")
    """An opponent counts as overtaken once it is this far behind the ego [m]."""
    respawn_distance: float = real(400.0, gt=0.0, unit="m")
    """An overtaken opponent reappears this far ahead of the ego [m]."""
    respawn_clearance: float = real(15.0, ge=0.0, unit="m")
    """Minimum arc-length spacing to another opponent on the same side at respawn [m]."""
    pace: PaceConfig = nested(PaceConfig)
    """Per-car pace ratios and lifts (off by default)."""
    lines: LineConfig = nested(LineConfig)
    """Own lines around the offsets (off by default)."""
    defence: DefenceConfig = nested(DefenceConfig)
    """Defending against the ego (off by default)."""
    traffic: TrafficConfig = nested(TrafficConfig)
    """Keeping clear of each other (used when any behaviour is on)."""

    def __post_init__(self) -> None:
        check_fields(self, _PATH)
        _check(self.n_opponents == 0 or (len(self.offsets) > 0 and len(self.gaps) > 0),
               f"{_PATH}.offsets and {_PATH}.gaps need at least one entry")
        _check(self.n_opponents <= len(self.gaps) or max(self.gaps) > 0.0,
               f"with more opponents than gaps, the largest gap of {_PATH}.gaps must be > 0 (the list repeats "
               "shifted by it)")

    @property
    def interactive(self) -> bool:
        """Whether any behaviour is on (otherwise the cars move exactly as in the paper)."""
        return self.pace.active or self.lines.active or self.defence.active

    def offset(self, i: int) -> float:
        return float(self.offsets[i % len(self.offsets)])

    def gap(self, i: int) -> float:
        k = len(self.gaps)
        return float(self.gaps[i % k]) + (i // k) * max(self.gaps)
