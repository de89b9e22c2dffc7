"""Configuration of the race world (:class:`RaceConfig`), validated in one place.

The race itself is :class:`sofar_env.race.Race`; this module holds its frozen configuration
(time step, horizon, plant, start and grid, opponents, sensing) and the limits it checks.
"""

from __future__ import annotations

from dataclasses import dataclass

from ..constants import MAX_SPEED_FACTOR
from ..domains import check_fields, choice, flag, integer, is_real, nested, real, reals
from ..errors import ConfigError
from .opponents import OpponentConfig
from .sensing import SensorConfig
from .vehicle import AV21, AV21_DYNAMIC, DynamicParams, VehicleParams

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


def _is_real(x) -> bool:
    """``x`` is a real number (Python or numpy int or float), not a bool."""
    return is_real(x)


@dataclass(frozen=True)
class RaceConfig:
    """World parameters.

    The ``grid_*`` fields place the controlled cars of a multi-car race (see the module docstring):
    pole at the drawn start, cars ``2r`` / ``2r + 1`` of row ``r`` at ``r grid_row_spacing`` /
    ``r grid_row_spacing + grid_stagger`` behind it, ``+-grid_lateral_offset`` beside the raceline.
    ``pace_range`` is the range of the cars' speed factors drawn per episode in the PettingZoo race.
    All are validated here.
    """

    dt: float = real(0.1, gt=0.0, unit="s")
    """Control period of the plant [s]."""
    duration: float = real(200.0, gt=0.0, unit="s")
    """Episode horizon [s]."""
    plant_substeps: int = integer(4, ge=1)
    """RK4 sub-steps per control period."""
    random_start: bool = flag(True)
    """Draw the ego start arc length uniformly on the raceline; otherwise use ``start_s``."""
    start_s: float = real(0.0, unit="m")
    """Start arc length when ``random_start`` is False [m]."""
    start_speed_fraction: tuple[float, float] = reals((0.5, 0.9), size=2, ge=0.0, le=1.5, ordered=True)
    """Start speed drawn uniformly in this range times the speed profile at the start [-]."""
    grid_row_spacing: float = real(24.0, ge=0.0, unit="m")
    """Multi-car start: arc length between the first cars of consecutive grid rows [m]."""
    grid_stagger: float = real(12.0, ge=0.0, unit="m")
    """Multi-car start: the second car of a row starts this far (arc length) behind the first [m]."""
    grid_lateral_offset: float = real(2.0, ge=0.0, unit="m")
    """Multi-car start: the first car of a row starts this far left of the raceline, the second as far
    right (moved inwards where the footprint would come within ``START_EDGE_MARGIN`` of an edge) [m]."""
    pace_range: tuple[float, float] = reals((0.9, 1.0), size=2, gt=0.0, le=MAX_SPEED_FACTOR, ordered=True)
    """Multi-car races (the PettingZoo environment): each controlled car's speed factor (its speed reference
    as a fraction of the speed profile) is drawn uniformly in this range at every reset, unless the
    environment is given ``speed_factors``; single-car races use ``stack.speed_factor`` [-]."""
    v2v: bool = flag(False)
    """Multi-car races: each controlled car publishes its MPC plan and the other controlled cars predict it
    from that plan instead of from its sensed speed (:mod:`sofar_env.v2v`); off: prediction from sensing only."""
    side_lock: float = real(6.0, ge=0.0, unit="m")
    """Multi-car races: the controlled cars' passing-side planners keep the side of every car within this
    arc-length gap, i.e. alongside (``stack.miqp.alongside_gap``, see :mod:`sofar_env.planning.miqp`), unless
    the user's keys set that gap themselves (the multi-car layer,
    :func:`~sofar_env.configs.resolve.multi_car_overrides`); 0 turns it off. No effect in single-car races [m],
    >= 0. Decision: ``docs/decisions/multi-car-defaults.md``."""
    lateral_rates: str = choice("mpc", LATERAL_RATES)
    """Multi-car races: what the controllers do with the other cars' lateral rates n_dot (the true rates, or
    the sensor's estimates with ``race.sensor`` on). ``"mpc"``: each controller's MPC gets them (its barrier
    rows move with the cars), its passing-side planners see the cars where they are
    (``stack.lateral_prediction_plan`` False); ``"all"``: the planners also see each car where its move ends;
    ``"off"``: without a sensor, rows (s, n, v) only, as in single-car races of the paper's world. The user's
    own ``stack.lateral_prediction_plan`` wins. No effect in single-car races and with ``stack.lateral_prediction``
    off (the paper preset). Decision: ``docs/decisions/multi-car-defaults.md``."""
    mpc_restart_slack: float = real(0.05, gt=0.0, inf="off")
    """Multi-car races: the controlled cars' MPCs solve once more from a cold guess when a warm-started solve
    needs more DCBF slack than this, and keep the better solution (``stack.mpc.restart_slack``, see
    :mod:`sofar_env.control.mpc.rti`), unless the user's keys set ``stack.mpc.restart_slack``; inf turns it off.
    No effect in single-car races [-], > 0. Decision: ``docs/decisions/multi-car-defaults.md``."""
    heading_extent: float = real(2.45, ge=0.0, unit="m")
    """Multi-car races: the controlled cars' barrier widens its lateral semi-axis with the car's own heading
    error to the track and the other car's course angle (from its lateral rate; ``stack.mpc.barrier.
    heading_extent``, see :mod:`sofar_env.control.barrier`), unless the user's keys set
    ``stack.mpc.barrier.heading_extent``; 0 adds nothing, so the controller keeps its own value (2.45 m in
    the default ``"sofar-17"``, by the turns toward the other car, and in ``"sofar-13"``; 0 in ``"sofar-6"`` and
    before). The rewards and the observation measure the barrier without this widening
    (:class:`~sofar_env.core.ControlledRace`). No effect in single-car races [m], >= 0. Decision:
    ``docs/decisions/multi-car-defaults.md``."""
    vehicle: VehicleParams = nested(VehicleParams, default=AV21)
    """Parameters of every car."""
    opponents: OpponentConfig = nested(OpponentConfig)
    """The scripted opponent field."""
    plant: str = choice("kinematic", PLANTS)
    """``"kinematic"``: the bicycle with slip of :mod:`sofar_env.vehicle` (the MPC's own model, the paper's
    world); ``"dynamic"``: the single-track model with Pacejka tyres and actuator lags of
    :mod:`sofar_env.dynamics`, with a friction coefficient mu drawn per episode in ``dynamic.mu_range``."""
    dynamic: DynamicParams = nested(DynamicParams, default=AV21_DYNAMIC)
    """Parameters of the dynamic plant (used with ``plant="dynamic"``)."""
    sensor: SensorConfig = nested(SensorConfig)
    """How the controllers and the observation see the opponents (off: perfect sensing)."""

    def __post_init__(self) -> None:
        """Check every field's domain (:mod:`sofar_env.domains`), then the checks that relate fields; raises
        :class:`~sofar_env.errors.ConfigError` naming the key."""
        check_fields(self, "race")
        if self.duration < self.dt:
            raise ConfigError(f"race.duration ({self.duration} s) must be at least one step (dt = {self.dt} s)")
        need = self.vehicle.length + GRID_MIN_GAP
        if self.grid_stagger < need or self.grid_row_spacing - self.grid_stagger < need:
            raise ConfigError(f"race.grid_stagger ({self.grid_stagger:g} m) and race.grid_row_spacing - grid_stagger "
                              f"({self.grid_row_spacing - self.grid_stagger:g} m) must each be at least the car "
                              f"length plus {GRID_MIN_GAP:g} m ({need:g} m), so that no two cars overlap at the start")

    @property
    def max_steps(self) -> int:
        return int(round(self.duration / self.dt))
