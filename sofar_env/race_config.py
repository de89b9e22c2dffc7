"""Configuration of the race world (:class:`RaceConfig`), validated in one place.

The race itself is :class:`sofar_env.race.Race`; this module holds its frozen configuration
(time step, horizon, plant, start and grid, opponents, sensing) and the limits it checks.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .dynamics import AV21_DYNAMIC, DynamicParams
from .opponents import OpponentConfig
from .sensing import SensorConfig
from .vehicle import AV21, VehicleParams

__all__ = ["RaceConfig", "PLANTS", "LATERAL_RATES", "START_EDGE_MARGIN", "MAX_START_SPEED_FACTOR",
           "GRID_MIN_GAP", "MAX_SPEED_FACTOR"]


PLANTS = ("kinematic", "dynamic")
"""Plant models of :attr:`RaceConfig.plant`."""
LATERAL_RATES = ("mpc", "all", "off")
"""Values of :attr:`RaceConfig.lateral_rates`."""
START_EDGE_MARGIN = 0.5
"""Distance kept between a controlled car's footprint and the track edge at the start [m]."""
MAX_START_SPEED_FACTOR = 1.1
"""A start speed may exceed the circuit's fastest speed-profile value by at most this factor."""
GRID_MIN_GAP = 2.0
"""Smallest bumper-to-bumper arc-length gap between consecutive grid slots (``grid_stagger`` and
``grid_row_spacing - grid_stagger`` less the car length) [m]."""
MAX_SPEED_FACTOR = 1.5
"""Largest speed factor of a stack (``StackConfig.speed_factor``) [-]."""


def _is_real(x) -> bool:
    return isinstance(x, (int, float, np.integer, np.floating)) and not isinstance(x, (bool, np.bool_))


@dataclass(frozen=True)
class RaceConfig:
    """World parameters.

    The ``grid_*`` fields place the controlled cars of a multi-car race (see the module docstring):
    pole at the drawn start, cars ``2r`` / ``2r + 1`` of row ``r`` at ``r grid_row_spacing`` /
    ``r grid_row_spacing + grid_stagger`` behind it, ``+-grid_lateral_offset`` beside the raceline.
    ``pace_range`` is the range of the cars' speed factors drawn per episode in the PettingZoo race.
    All are validated here.
    """

    dt: float = 0.1
    """Control period of the plant [s]."""
    duration: float = 200.0
    """Episode horizon [s]."""
    plant_substeps: int = 4
    """RK4 sub-steps per control period."""
    random_start: bool = True
    """Draw the ego start arc length uniformly on the raceline; otherwise use ``start_s``."""
    start_s: float = 0.0
    """Start arc length when ``random_start`` is False [m]."""
    start_speed_fraction: tuple[float, float] = (0.5, 0.9)
    """Start speed drawn uniformly in this range times the speed profile at the start [-]."""
    grid_row_spacing: float = 24.0
    """Multi-car start: arc length between the first cars of consecutive grid rows [m]."""
    grid_stagger: float = 12.0
    """Multi-car start: the second car of a row starts this far (arc length) behind the first [m]."""
    grid_lateral_offset: float = 2.0
    """Multi-car start: the first car of a row starts this far left of the raceline, the second as far
    right (moved inwards where the footprint would come within ``START_EDGE_MARGIN`` of an edge) [m]."""
    pace_range: tuple[float, float] = (0.9, 1.0)
    """Multi-car races (the PettingZoo environment): each controlled car's speed factor (its speed reference
    as a fraction of the speed profile) is drawn uniformly in this range at every reset, unless the
    environment is given ``speed_factors``; single-car races use ``stack.speed_factor`` [-]."""
    v2v: bool = False
    """Multi-car races: each controlled car publishes its MPC plan and the other controlled cars predict it
    from that plan instead of from its sensed speed (:mod:`sofar_env.v2v`); off: prediction from sensing only."""
    side_lock: float = 6.0
    """Multi-car races: the controlled cars' passing-side planners keep the side of every car within this
    arc-length gap, i.e. alongside (``stack.miqp.alongside_gap``, see :mod:`sofar_env.planning.miqp`), unless
    the stack config sets its own non-zero gap; 0 turns it off. No effect in single-car races [m]."""
    lateral_rates: str = "mpc"
    """Multi-car races: what the controllers do with the other cars' lateral rates n_dot (the true rates, or
    the sensor's estimates with ``race.sensor`` on). ``"mpc"``: each controller's MPC gets them (its barrier
    rows move with the cars), its passing-side planners see the cars where they are
    (``stack.lateral_prediction_plan`` False); ``"all"``: the planners also see each car where its move ends;
    ``"off"``: without a sensor, rows (s, n, v) only, as in single-car races of the paper's world. No effect
    in single-car races and with ``stack.lateral_prediction`` off (the paper preset)."""
    mpc_restart_slack: float = 0.05
    """Multi-car races: the controlled cars' MPCs solve once more from a cold guess when a warm-started solve
    needs more DCBF slack than this, and keep the better solution (``stack.mpc.restart_slack``, see
    :mod:`sofar_env.control.mpc.rti`), unless the stack config sets its own finite value; inf turns it off.
    No effect in single-car races [-]."""
    heading_extent: float = 2.45
    """Multi-car races: the controlled cars' barrier widens its lateral semi-axis with the car's own heading
    error to the track and the other car's course angle (from its lateral rate; ``stack.mpc.barrier.
    heading_extent``, see :mod:`sofar_env.control.barrier`; half the car length covers a car's rotation),
    unless the stack config sets its own non-zero value; 0 turns it off. No effect in single-car races [m]."""
    vehicle: VehicleParams = AV21
    """Parameters of every car."""
    opponents: OpponentConfig = field(default_factory=OpponentConfig)
    """The scripted opponent field."""
    plant: str = "kinematic"
    """``"kinematic"``: the bicycle with slip of :mod:`sofar_env.vehicle` (the MPC's own model, the paper's
    world); ``"dynamic"``: the single-track model with Pacejka tyres and actuator lags of
    :mod:`sofar_env.dynamics`, with a friction coefficient mu drawn per episode in ``dynamic.mu_range``."""
    dynamic: DynamicParams = AV21_DYNAMIC
    """Parameters of the dynamic plant (used with ``plant="dynamic"``)."""
    sensor: SensorConfig = field(default_factory=SensorConfig)
    """How the controllers and the observation see the opponents (off: perfect sensing)."""

    def __post_init__(self) -> None:
        for name in ("dt", "duration"):
            value = getattr(self, name)
            if not (_is_real(value) and math.isfinite(value) and value > 0):
                raise ValueError(f"race.{name} must be a finite number > 0 [s], got {value!r}")
        if self.duration < self.dt:
            raise ValueError(f"race.duration ({self.duration} s) must be at least one step (dt = {self.dt} s)")
        if not (isinstance(self.plant_substeps, (int, np.integer)) and self.plant_substeps >= 1):
            raise ValueError(f"race.plant_substeps must be an integer >= 1, got {self.plant_substeps!r}")
        if not _is_real(self.start_s) or not math.isfinite(self.start_s):
            raise ValueError(f"race.start_s must be a finite number [m], got {self.start_s!r}")
        if len(self.start_speed_fraction) != 2:
            raise ValueError(f"race.start_speed_fraction must be a pair, got {self.start_speed_fraction!r}")
        lo, hi = self.start_speed_fraction
        if not (_is_real(lo) and _is_real(hi) and 0.0 <= lo <= hi <= 1.5):
            raise ValueError("race.start_speed_fraction must be an ordered pair in [0, 1.5] (fractions of the "
                             f"speed profile), got {self.start_speed_fraction!r}")
        if not (_is_real(self.side_lock) and math.isfinite(self.side_lock) and self.side_lock >= 0):
            raise ValueError(f"race.side_lock must be a finite number >= 0 [m], got {self.side_lock!r}")
        if self.lateral_rates not in LATERAL_RATES:
            raise ValueError(f"race.lateral_rates must be one of {', '.join(map(repr, LATERAL_RATES))}, "
                             f"got {self.lateral_rates!r}")
        if not (_is_real(self.mpc_restart_slack) and self.mpc_restart_slack > 0):
            raise ValueError(f"race.mpc_restart_slack must be a number > 0 (inf: off), got {self.mpc_restart_slack!r}")
        if not (_is_real(self.heading_extent) and math.isfinite(self.heading_extent) and self.heading_extent >= 0):
            raise ValueError(f"race.heading_extent must be a finite number >= 0 [m], got {self.heading_extent!r}")
        if not isinstance(self.v2v, (bool, np.bool_)):
            raise ValueError(f"race.v2v must be True or False, got {self.v2v!r}")
        if self.plant not in PLANTS:
            raise ValueError(f"race.plant must be one of {PLANTS}, got {self.plant!r}")
        self._check_grid()

    def _check_grid(self) -> None:
        for name in ("grid_row_spacing", "grid_stagger", "grid_lateral_offset"):
            value = getattr(self, name)
            if not (_is_real(value) and math.isfinite(value) and value >= 0):
                raise ValueError(f"race.{name} must be a finite number >= 0 [m], got {value!r}")
        need = self.vehicle.length + GRID_MIN_GAP
        if self.grid_stagger < need or self.grid_row_spacing - self.grid_stagger < need:
            raise ValueError(f"race.grid_stagger ({self.grid_stagger:g} m) and race.grid_row_spacing - grid_stagger "
                             f"({self.grid_row_spacing - self.grid_stagger:g} m) must each be at least the car "
                             f"length plus {GRID_MIN_GAP:g} m ({need:g} m), so that no two cars overlap at the start")
        pace = self.pace_range
        if not (isinstance(pace, (tuple, list)) and len(pace) == 2 and all(_is_real(p) for p in pace)
                and 0.0 < pace[0] <= pace[1] <= MAX_SPEED_FACTOR):
            raise ValueError(f"race.pace_range must be an ordered pair in (0, {MAX_SPEED_FACTOR:g}] (speed factors), "
                             f"got {pace!r}")

    @property
    def max_steps(self) -> int:
        return int(round(self.duration / self.dt))
