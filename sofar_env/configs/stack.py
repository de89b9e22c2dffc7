"""Configuration of the overtaking stack (:class:`StackConfig`): values only, importable without the solvers.

:class:`StackConfig` holds every setting of the hierarchical controller (:mod:`sofar_env.stack`): the speed
reference, the MIQP schedule, the opponents' window, the pass-or-follow decision
(:mod:`sofar_env.stack.follow`), the opponent prediction (:mod:`sofar_env.stack.prediction`), the
footprint-aware track edges (:mod:`sofar_env.stack.edges`) and the two planners' own configurations. The
named controllers are entries of :mod:`sofar_env.configs.registry` (:func:`sofar_env.stack.stack_preset`).

The default MIQP configuration also closes a gap between the two planners (*consistent clearances*): the
MIQP's side-constraint window is extended by the braking distance of the closing speed
(``MIQPConfig.closing_decel`` = the barrier's ``a_brake``), the shape of the MPC's barrier ellipse, so that a
plan crossing an opponent's lane inside its braking distance, which the barrier then forbids, is no longer
produced.
"""

from __future__ import annotations

from dataclasses import dataclass

from ..constants import MAX_SPEED_FACTOR
from ..domains import check_fields, flag, integer, nested, neutral, real
from ..errors import ConfigError
from .miqp import MIQPConfig
from .mpc import BarrierParams, MPCConfig
from .refnum import ReferenceNumerics

__all__ = ["StackConfig"]


@dataclass(frozen=True)
class StackConfig:
    """Configuration of the hierarchical controller."""

    speed_factor: float = real(0.8, gt=0.0, le=MAX_SPEED_FACTOR)
    """Ego speed reference = speed_factor x the circuit's speed profile [-]."""
    use_miqp: bool = flag(True)
    """Run the passing-side MIQP; when False the MPC tracks the raceline (n_ref = 0)."""
    miqp_interval: int = integer(2, ge=1)
    """Run the MIQP every this many control steps (1 = every step)."""
    look_behind: float = real(30.0, ge=0.0, unit="m")
    """Opponents up to this far behind the ego are passed to the planners [m]."""
    look_ahead: float = real(400.0, ge=0.0, unit="m")
    """Opponents up to this far ahead of the ego are passed to the planners [m]."""
    follow: bool = flag(True)
    """Follow an opponent that cannot be passed instead of forcing the pass (:mod:`sofar_env.stack.follow`)."""
    follow_slack: float = real(0.5, ge=0.0, unit="m")
    """A passing plan that violates the clearance of an opponent ahead by more than this is
    not attempted: the ego follows that opponent [m], >= 0. A pass is planned with at least
    ``miqp.safe_lat - follow_slack`` lateral clearance. Decision: ``docs/decisions/follow-clearance.md``."""
    follow_release_slack: float = real(0.1, ge=0.0, unit="m")
    """Hysteresis of the follow decision [m], in [0, ``follow_slack``]: while following, an opponent ahead
    stays blocked until the passing plan violates its clearance by at most this (entering takes
    ``follow_slack``). Decision: ``docs/decisions/follow-clearance.md``."""
    follow_queue: bool = neutral(flag(False))
    """Follow the queue (False: the default): when the plan that follows the blocked opponents violates the clearance
    of a nearer car ahead that it passes by more than ``follow_slack``, and the ego can stay behind that car, it is
    followed too (and so on, at most once per opponent). Without it such a follow plan can be no better than the
    pass, and the pass is then held although it violates a car further ahead by metres: the ego passes one car into
    a corner where the next holds the line (``docs/decisions/follow-clearance.md``, "Following the queue")."""
    follow_recheck: int = integer(2, ge=1)
    """While following, the passing plan is re-examined at every this-many-th MIQP call (1: at
    every call). In between, only the follow plan is re-solved, for the same followed cars
    (matched by their predicted positions); a follow plan that then violates the clearance of a
    car it passes by more than ``follow_slack``, or a followed car that is no longer found, falls
    back to the full pass-or-follow decision. Resuming a pass waits at most
    ``(follow_recheck - 1) miqp_interval`` more steps [-], >= 1. Decision: ``docs/decisions/follow-clearance.md``."""
    follow_gap: float = real(12.0, ge=0.0, unit="m")
    """Arc-length distance kept behind a followed opponent [m] (the barrier's a0 = 7 m plus 5 m)."""
    follow_decel: float = real(5.0, gt=0.0, unit="m/s^2")
    """Deceleration planned when following [m/s^2]: the speed reference is capped at
    sqrt(v_o^2 + 2 follow_decel (gap - follow_gap)), the speed from which the ego reaches the
    opponent's speed ``follow_gap`` behind it, and the MIQP node positions brake at this rate."""
    follow_reach_decel: float = real(8.0, gt=0.0, unit="m/s^2")
    """Deceleration [m/s^2] that decides whether the ego can still stay behind an opponent
    (:meth:`~sofar_env.stack.follow.PassOrFollow.can_stay_behind`); if not, the pass is not abandoned."""
    follow_alongside: bool = flag(True)
    """Also follow a blocking car the ego is alongside or less than the barrier's a0 behind,
    when braking at ``follow_reach_decel`` drops the ego behind it (else such a pass is held)."""
    parked_pass: bool = flag(True)
    """Pass a near-stationary opponent with the barrier's clearance when the passing clearance does not fit
    (:mod:`sofar_env.stack.follow`): instead of following a car slower than ``parked_speed``, which would
    stop the ego behind it for good, the pass is re-planned with a side-constraint window shaped like the
    MPC's barrier ellipse (lateral semi-axis ``parked_clearance``, longitudinal ``parked_window`` plus the
    braking distance of the closing speed), and a car is followed only if that plan enters the barrier's
    own ellipse around it. While such a plan is in force the MPC measures the swing of the car's ends
    against the edges' directions (:meth:`~sofar_env.stack.edges.TrackEdges.for_mpc`). Only with
    ``follow``, and only when every opponent the passing plan has to clear is near-stationary."""
    parked_speed: float = real(1.0, ge=0.0, unit="m/s")
    """An opponent slower than this counts as near-stationary (parked) [m/s], >= 0. Decision:
    ``docs/decisions/parked-pass.md``."""
    parked_clearance: float = real(3.0, unit="m")
    """Lateral semi-axis [m] of the passing plan's elliptic window around a near-stationary opponent (instead
    of the box window ``miqp.safe_lat``), in (0, ``miqp.safe_lat``]; the decision to follow only needs the
    barrier's own ellipse. Decision: ``docs/decisions/parked-pass.md``."""
    parked_window: float = real(7.0, unit="m")
    """Longitudinal semi-axis [m] of that window at zero closing speed (it grows by the braking distance of
    the closing speed, ``miqp.closing_decel``, on the approach), in (0, ``miqp.safe_lon``]. Decision:
    ``docs/decisions/parked-pass.md``."""
    pace_prediction: bool = flag(True)
    """Predict the opponents along the speed profile at their current pace ratio
    (:class:`~sofar_env.stack.prediction.OpponentPredictor`) instead of at constant speed: the MIQP gets
    the predicted positions, the MPC (constant-speed opponents) the mean speed over its horizon."""
    lateral_prediction: bool = flag(True)
    """Predict the opponents' lateral motion from the sensed lateral rate (the fourth column of the
    rows given to :meth:`~sofar_env.stack.OvertakingStack.step`, e.g. the tracker estimate of
    :mod:`sofar_env.sensing`; rows of three columns are predicted at a constant offset): over
    ``lateral_prediction_time`` a car keeps moving at its rate less ``lateral_rate_deadband``, inside the
    edges; the MPC's barrier rows get that motion, the MIQP and the follow logic the offset where it ends
    (:func:`~sofar_env.stack.prediction.lateral_motion`)."""
    lateral_prediction_plan: bool = flag(True)
    """With ``lateral_prediction``: the MIQP and the follow logic see each car at the offset where its lateral
    move ends (True), or where it is now (False); the MPC's barrier rows get the motion either way."""
    lateral_prediction_time: float = real(1.5, gt=0.0, unit="s")
    """How long a sensed lateral rate is carried forward [s], > 0. Decision:
    ``docs/decisions/lateral-prediction.md``."""
    lateral_rate_deadband: float = real(0.3, ge=0.0, unit="m/s")
    """Lateral rates are shrunk toward zero by this much before they are used [m/s], >= 0 (a soft
    threshold, continuous in the rate). Decision: ``docs/decisions/lateral-prediction.md``."""
    footprint_edges: bool = flag(True)
    """Give the planners the narrowest edge within the car's length, and tighten the MPC's by
    the heading error (:mod:`sofar_env.stack.edges`). With ``mpc.track_rows = "ends"`` the MPC bounds
    the car's ends in its QP instead (also with ``"recoverable"``), and its edges are not tightened by
    the heading error."""
    restart_lateral_weight: float | None = neutral(real(None, ge=0.0, optional="off", unit="1/m^2"))
    """*Restart mode* (None: off, the default). While the ego is slower than ``restart_speed`` under a speed
    reference of at least ``restart_speed``, and from then on until it is ``restart_exit_speed`` fast, the MPC
    step is solved by a second MPC whose lateral-tracking weight ``mpc.q[1]`` is this value (entered from a
    cold start; the stack's own MPC restarts cold when the mode ends), and a plan that stays below
    ``restart_speed`` while the car is turned by the turn-back angle ``e*``
    (:class:`~sofar_env.control.mpc.ends.EndOffsets`) or more steers towards full lock on the side that turns
    it back (at standstill the model gives steering no effect). Over a horizon shorter than the turn back, the
    full lateral weight makes a standstill turned away from the lateral reference the MPC's optimum [1/m^2],
    >= 0. Decision: ``docs/decisions/stall-fixes.md``."""
    restart_speed: float = neutral(real(1.0, gt=0.0, unit="m/s"))
    """Speed below which the restart mode starts [m/s], > 0 (only with ``restart_lateral_weight``)."""
    restart_exit_speed: float = neutral(real(3.0, gt=0.0, unit="m/s"))
    """Speed at which the restart mode ends [m/s], >= ``restart_speed``."""
    restart_buffer_edge: float | None = neutral(real(None, ge=0.0, optional="off", unit="m"))
    """The restart mode's *buffer slack* (None: off, the default; only with the restart mode and end rows in its
    MPC: ``slow_rows_speed``, or ``mpc.track_rows`` other than ``"reference"``). The track margin keeps the car's
    side ``mpc.track_margin - width / 2`` from each edge (0.25 m in the paper's worlds, 1.25 m in the dynamic
    world); with this set, the end rows of the restart mode's MPC pay ``mpc.track_buffer_slack`` instead of
    ``mpc.track_slack`` for a violation of the margin until the side comes this close to the edge
    (``mpc.track_buffer`` of that MPC; 0 where the margin leaves no such band), so that a car standing inside the
    margin drives off along it instead of standing, while the last metres to the edge stay as expensive as
    without it. Above ``restart_exit_speed`` nothing changes [m], >= 0. Decision: ``docs/decisions/stall-fixes.md``."""
    restart_buffer_scale: float | None = neutral(real(None, gt=0.0, le=1.0,
                                                      optional="mpc.track_buffer_slack as it is"))
    """The restart mode's buffer-slack weights as a share of ``mpc.track_buffer_slack`` (None: 1, the default;
    only with ``restart_buffer_edge``): the other MPCs and the rest of the margin keep their weights. Lower, a car
    at rest with its end inside the margin's band drives off along it sooner, where every moving plan takes the
    end deeper into the band [-], in (0, 1]. Measured (the candidate ``"sofar-9"``, 0.25):
    ``docs/decisions/stall-fixes.md``, "Standing in a tight corner"."""
    restart_horizon: int | None = neutral(integer(None, ge=2, optional="mpc.horizon"))
    """Stages of the restart mode's MPC (None: ``mpc.horizon``, the default; only with the restart mode), on the
    MPC's time grid (``mpc.ts`` apart after the first step); its stage data are looked up along its own warm start
    and :attr:`~sofar_env.stack.OvertakingStack.plan_times` gives the times of its plan [-], >= 2. Measured (the
    candidates ``"sofar-7"`` and ``"sofar-8"``, not adopted): ``docs/decisions/stall-fixes.md``."""
    restart_heading_extent: float | None = neutral(real(None, ge=0.0, optional="mpc.barrier.heading_extent",
                                                        unit="m"))
    """``mpc.barrier.heading_extent`` of the restart mode's MPC (None: the MPC's own, the default; only with the
    restart mode): the barrier's lateral semi-axis widened with the heading error, so that a car turned at low
    speed keeps its corners, not only its centre, clear of a car beside it (the ellipse of aligned cars does not
    cover a turned footprint) [m], >= 0. Decision: ``docs/decisions/stall-fixes.md``."""
    follow_creep_speed: float = neutral(real(0.0, ge=0.0, unit="m/s"))
    """*Turned-car creep* (0: off, the default). While a car is followed and the ego is turned to the track by
    more than ``follow_creep_angle``, and until it is turned by less than ``follow_creep_release``, the follow
    speed cap is raised to at least this speed at the stages where every followed car is predicted more than
    the barrier's ``a0`` ahead, so that a follow decision does not brake a car to a stop in the middle of a
    lateral move (the DCBF still keeps the distance) [m/s], >= 0. Decision: ``docs/decisions/stall-fixes.md``."""
    follow_creep_angle: float = neutral(real(0.3, gt=0.0, unit="rad"))
    """|Heading error| above which the creep starts [rad], > 0."""
    follow_creep_release: float = neutral(real(0.2, ge=0.0, unit="rad"))
    """|Heading error| below which the creep ends [rad], in [0, ``follow_creep_angle``]."""
    slow_rows_speed: float | None = neutral(real(None, gt=0.0, optional="off", unit="m/s"))
    """*Slow end rows* (None: off, the default; only with ``mpc.track_rows = "reference"``). While the ego is
    slower than this, and from then on until it is ``slow_rows_exit_speed`` fast, the MPC step is solved by a
    second MPC that bounds both ends of the car with room kept for turning back (``track_rows =
    "recoverable"``, :mod:`sofar_env.control.mpc.ends`; entered from a cold start, the stack's own MPC restarts
    cold when it ends); the restart mode's MPC bounds them too. At racing speed the MPC keeps the reference
    point's rows, whose edges the footprint-aware edges tighten [m/s], > 0. Decision:
    ``docs/decisions/stall-fixes.md``."""
    slow_rows_exit_speed: float = neutral(real(12.0, gt=0.0, unit="m/s"))
    """Speed at which the slow end rows end [m/s], >= ``slow_rows_speed``."""
    slow_rows_curved: bool = neutral(flag(False))
    """Whether the slow end rows (and the restart mode's) count the track's curvature in the room kept for turning
    back (``track_rows = "recoverable-curved"``: in a corner a car turned towards the outside edge needs more);
    only with ``slow_rows_speed``. Decision: ``docs/decisions/stall-fixes.md``."""
    parked_follow_gap: float | None = neutral(real(None, ge=0.0, optional="follow_gap", unit="m"))
    """Arc-length distance kept behind a followed car slower than ``parked_speed`` [m] (None: ``follow_gap``,
    the default), so that the ego stops where it can still steer around a near-stationary car. Decision:
    ``docs/decisions/stall-fixes.md``."""
    mpc: MPCConfig = nested(MPCConfig)
    """The low-level MPC-DCBF."""
    miqp: MIQPConfig = nested(MIQPConfig, factory=lambda: MIQPConfig(closing_decel=BarrierParams().a_brake))
    """The passing-side planner (its closing-speed window sized by the barrier's a_brake: the
    consistent clearances of this module's docstring)."""
    reference_numerics: ReferenceNumerics | None = nested(ReferenceNumerics, default=None, optional="the MPC-DCBF")
    """None (every preset but one): the MPC-DCBF of :mod:`sofar_env.control.mpc`. Set: the low-level
    controller is the **bug-compatible** MPC of :mod:`sofar_env.control.refnum`, which reproduces the
    numerical defects of the paper's reference implementation (phantom opponents, soft barrier rows
    bounded at -1e9, HPIPM's iteration cap, a zero command on failure). Only the preset
    ``"reference-numerics"`` sets it; ``mpc`` then gives its time grid and weights."""

    def __post_init__(self) -> None:
        """Check every field's domain (:mod:`sofar_env.domains`), then the checks that relate fields; raises
        :class:`~sofar_env.errors.ConfigError` naming the key."""
        check_fields(self, "stack")
        if not self.follow_release_slack <= self.follow_slack:
            raise ConfigError(f"stack.follow_release_slack must lie in [0, follow_slack = {self.follow_slack}] "
                              f"[m], got {self.follow_release_slack!r}")
        if not self.restart_speed <= self.restart_exit_speed:
            raise ConfigError(f"stack.restart_exit_speed must be >= restart_speed = {self.restart_speed} [m/s], "
                              f"got {self.restart_exit_speed!r}")
        if self.slow_rows_speed is not None:
            if self.mpc.track_rows != "reference":
                raise ConfigError(f"stack.slow_rows_speed needs stack.mpc.track_rows = 'reference' (it switches to "
                                  f"the 'recoverable' rows below that speed), got {self.mpc.track_rows!r}")
            if not self.slow_rows_speed <= self.slow_rows_exit_speed:
                raise ConfigError(f"stack.slow_rows_exit_speed must be >= slow_rows_speed = {self.slow_rows_speed} "
                                  f"[m/s], got {self.slow_rows_exit_speed!r}")
            if self.restart_lateral_weight is not None and self.slow_rows_speed < self.restart_exit_speed:
                raise ConfigError(f"stack.slow_rows_speed must be >= restart_exit_speed = {self.restart_exit_speed} "
                                  f"[m/s] with the restart mode on (its MPC bounds the ends too), got "
                                  f"{self.slow_rows_speed!r}")
        if self.restart_buffer_edge is not None:
            if self.restart_lateral_weight is None:
                raise ConfigError("stack.restart_buffer_edge needs the restart mode (stack.restart_lateral_weight), "
                                  "got restart_lateral_weight = None")
            if self.slow_rows_speed is None and self.mpc.track_rows == "reference":
                raise ConfigError("stack.restart_buffer_edge needs end rows in the restart mode's MPC "
                                  "(stack.slow_rows_speed, or stack.mpc.track_rows other than 'reference')")
        if self.restart_buffer_scale is not None and self.restart_buffer_edge is None:
            raise ConfigError("stack.restart_buffer_scale needs the restart mode's buffer slack "
                              "(stack.restart_buffer_edge), got restart_buffer_edge = None")
        if self.restart_horizon is not None and self.restart_lateral_weight is None:
            raise ConfigError("stack.restart_horizon needs the restart mode (stack.restart_lateral_weight), "
                              "got restart_lateral_weight = None")
        if self.restart_heading_extent is not None and self.restart_lateral_weight is None:
            raise ConfigError("stack.restart_heading_extent needs the restart mode (stack.restart_lateral_weight), "
                              "got restart_lateral_weight = None")
        if self.slow_rows_curved and self.slow_rows_speed is None:
            raise ConfigError("stack.slow_rows_curved needs stack.slow_rows_speed (it is a property of the slow end "
                              "rows), got slow_rows_speed = None")
        if not self.follow_creep_release <= self.follow_creep_angle:
            raise ConfigError(f"stack.follow_creep_release must lie in [0, follow_creep_angle = "
                              f"{self.follow_creep_angle}] [rad], got {self.follow_creep_release!r}")
        if not 0.0 < self.parked_window <= self.miqp.safe_lon:
            raise ConfigError(f"stack.parked_window must lie in (0, miqp.safe_lon = {self.miqp.safe_lon}] [m], "
                              f"got {self.parked_window!r}")
        if not 0.0 < self.parked_clearance <= self.miqp.safe_lat:
            raise ConfigError(f"stack.parked_clearance must lie in (0, miqp.safe_lat = {self.miqp.safe_lat}] [m], "
                              f"got {self.parked_clearance!r}")
