"""Algorithm 1 of the paper: the hierarchical overtaking controller.

Per control step:

1. transform the ego and the opponents into the Frenet frame of the raceline
   (opponent arc lengths become signed gaps to the ego);
2. predict the opponents at constant velocity along the track (inside the
   planners, from the rows ``(gap, n, v)``);
3. every ``miqp_interval``-th step, solve the passing-side MIQP for a lateral
   reference ``d*`` over the coarse horizon;
4. take the barrier decay ``gamma`` from the caller (a policy, or fixed);
5. solve the MPC-DCBF with ``d*`` as the lateral reference and ``gamma``.

Additions to the paper's algorithm, each closing a failure mode seen in closed loop:

* **Pass or follow.** The MIQP plans lateral offsets only, with the ego's progress
  taken from its speed reference. When no passing side of an opponent ahead is
  clear (the plan violates that opponent's clearance by more than
  ``follow_slack``, e.g. the raceline runs to the edge on the passing side at the
  next corner, or the track is too narrow), attempting the pass ends alongside the
  opponent with the corridor closing. The stack then *follows* instead: it re-plans
  with the ego's node positions held ``follow_gap`` behind the blocking opponent(s)
  (no slower than braking at ``follow_decel`` allows) and caps the MPC speed
  reference at ``sqrt(v_o^2 + 2 follow_decel (gap - follow_gap))``, the speed from
  which braking at ``follow_decel`` ends at the opponent's speed ``follow_gap``
  behind it. An opponent behind which the ego can no longer stay (braking at
  ``follow_reach_decel`` the gap would shrink below ``min(gap, a0)``, or not reach
  the barrier's ``a0`` within the horizon) is not followed. A car the ego is already
  alongside is followed when braking drops the ego behind it (the follow plan keeps
  the ego's side of it until the ego is ``a0`` behind): holding such a pass is what
  squeezes the ego between that car and a closing edge at a corner entry.
  While following, the pass is re-examined at every ``follow_recheck``-th MIQP call (in
  between only the follow plan is re-solved), with hysteresis: a pass is resumed only
  once its clearance violation has fallen to ``follow_release_slack``.
* **Footprint-aware track edges.** Leaving the track is judged on the footprint's
  corners, the MPC keeps its reference point ``track_margin`` from the edge. The
  edges given to the planners are the narrowest within the car's length around
  each predicted position (edges converge on the raceline by up to 0.5 m per metre
  in chicanes), and the MPC's are further tightened by ``max(l_f, l_r) |sin e|``
  with the heading error ``e`` of the previous prediction (how far a corner swings
  out when the car is not aligned with the track).
* **Consistent clearances.** The MIQP's side-constraint window is extended by the
  braking distance of the closing speed (``MIQPConfig.closing_decel`` = the
  barrier's ``a_brake``), the shape of the MPC's barrier ellipse; a plan that
  crosses an opponent's lane inside its braking distance, which the barrier then
  forbids, is no longer produced.

The stack never raises on numerical trouble: the planners return fallbacks,
which are counted (:attr:`OvertakingStack.counters`).
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass, field

import numpy as np

from ._gradient import GridGradient
from ._interp import interp as _interp
from .control.barrier import BarrierParams
from .control.mpc import MPCConfig, MPCDCBF, MPCResult, MPCStageData
from .planning.miqp import MIQPConfig, PassingSidePlanner, PlanResult
from .vehicle import AV21, VehicleParams


__all__ = ["StackConfig", "StackOutput", "OvertakingStack", "STACK_PRESETS", "stack_preset"]


@dataclass(frozen=True)
class StackConfig:
    """Configuration of the hierarchical controller."""

    speed_factor: float = 0.8
    """Ego speed reference = speed_factor x the circuit's speed profile [-]."""
    use_miqp: bool = True
    """Run the passing-side MIQP; when False the MPC tracks the raceline (n_ref = 0)."""
    miqp_interval: int = 2
    """Run the MIQP every this many control steps (1 = every step)."""
    look_behind: float = 30.0
    """Opponents up to this far behind the ego are passed to the planners [m]."""
    look_ahead: float = 400.0
    """Opponents up to this far ahead of the ego are passed to the planners [m]."""
    follow: bool = True
    """Follow an opponent that cannot be passed instead of forcing the pass (module docstring)."""
    follow_slack: float = 0.5
    """A passing plan that violates the clearance of an opponent ahead by more than this is
    not attempted: the ego follows that opponent [m]. With 0.5 m a pass is planned with at
    least 3.25 m lateral clearance (safe_lat 3.75 m), 0.55 m more than the barrier's lateral
    semi-axis b = 2.7 m: a pass planned at about b stalls alongside the opponent (the barrier
    is near 0 there and, for small gamma, may only decay slowly), and a looser 0.8 m led to
    exactly that, and a collision, on Kentucky at rho = 0.1, gamma = 0.05."""
    follow_release_slack: float = 0.1
    """Hysteresis of the follow decision [m]: while following, an opponent ahead stays blocked
    until the passing plan violates its clearance by at most this (entering takes
    ``follow_slack``). Without it the decision can flicker every MIQP call near the threshold,
    and each flicker trades braking for a pass attempt (Laguna Seca, last corner)."""
    follow_recheck: int = 2
    """While following, the passing plan is re-examined at every this-many-th MIQP call (1: at
    every call). In between, only the follow plan is re-solved, for the same followed cars
    (matched by their predicted positions); a follow plan that then violates the clearance of a
    car it passes by more than ``follow_slack``, or a followed car that is no longer found, falls
    back to the full pass-or-follow decision. It halves the second MIQP solve of most calls while
    following; resuming a pass waits at most ``(follow_recheck - 1) miqp_interval`` more steps."""
    follow_gap: float = 12.0
    """Arc-length distance kept behind a followed opponent [m] (the barrier's a0 = 7 m plus 5 m)."""
    follow_decel: float = 5.0
    """Deceleration planned when following [m/s^2]: the speed reference is capped at
    sqrt(v_o^2 + 2 follow_decel (gap - follow_gap)), the speed from which the ego reaches the
    opponent's speed ``follow_gap`` behind it, and the MIQP node positions brake at this rate."""
    follow_reach_decel: float = 8.0
    """Deceleration [m/s^2] that decides whether the ego can still stay behind an opponent
    (:meth:`OvertakingStack._can_stay_behind`); if not, the pass is not abandoned."""
    follow_alongside: bool = True
    """Also follow a blocking car the ego is alongside or less than the barrier's a0 behind,
    when braking at ``follow_reach_decel`` drops the ego behind it (else such a pass is held)."""
    pace_prediction: bool = True
    """Predict the opponents along the speed profile at their current pace ratio
    (:meth:`OvertakingStack.predict_opponents`) instead of at constant speed: the MIQP gets
    the predicted positions, the MPC (constant-speed opponents) the mean speed over its horizon."""
    footprint_edges: bool = True
    """Give the planners the narrowest edge within the car's length, and tighten the MPC's by
    the heading error (module docstring)."""
    mpc: MPCConfig = field(default_factory=MPCConfig)
    """The low-level MPC-DCBF."""
    miqp: MIQPConfig = field(default_factory=lambda: MIQPConfig(closing_decel=BarrierParams().a_brake))
    """The passing-side planner (its closing-speed window sized by the barrier's a_brake)."""

    def __post_init__(self) -> None:
        if not (0.0 < self.speed_factor <= 1.5):
            raise ValueError(f"speed_factor must lie in (0, 1.5], got {self.speed_factor}")
        if self.miqp_interval < 1:
            raise ValueError("miqp_interval must be >= 1")
        if int(self.follow_recheck) != self.follow_recheck or self.follow_recheck < 1:
            raise ValueError("follow_recheck must be an integer >= 1")
        if not 0.0 <= self.follow_release_slack <= self.follow_slack:
            raise ValueError("follow_release_slack must lie in [0, follow_slack]")
        for name in ("follow_slack", "follow_gap"):
            if not getattr(self, name) >= 0.0:
                raise ValueError(f"{name} must be >= 0")
        for name in ("follow_decel", "follow_reach_decel"):
            if not getattr(self, name) > 0.0:
                raise ValueError(f"{name} must be > 0")


STACK_PRESETS: tuple[str, ...] = ("sofar", "paper")
"""Names accepted by :func:`stack_preset` (and by the environments' ``stack=`` key)."""


def stack_preset(name: str) -> StackConfig:
    """The controller of a named preset.

    ``"sofar"`` (the default of every environment) is :class:`StackConfig` as it is:
    the paper's Algorithm 1 plus the additions described in this module's docstring.

    ``"paper"`` is the paper's Algorithm 1 as written, every addition of ours off:

    * ``follow=False``: no pass-or-follow decision; the MIQP always plans a pass of
      every opponent it sees (the paper has no following mode);
    * ``pace_prediction=False``: opponents are predicted at constant speed along the
      track, the paper's constant-velocity model;
    * ``footprint_edges=False``: the planners' track edges are the edges at the
      predicted reference point, not the narrowest within the car's length, and the MPC's
      are not tightened by the heading error;
    * ``miqp.closing_decel=0``: the MIQP's side constraints use the plain longitudinal
      window ``|gap| < safe_lon``, as in the paper's eq. (8), without the braking-distance
      extension.

    Where the paper leaves a choice open, both presets make the same one (so the
    difference between them is only the list above): the MIQP runs every second control
    step over 76 nodes 0.15 s apart; its side windows are ``safe_lon`` = 8 m and
    ``safe_lat`` = 3.75 m; it keeps the previous decision with a switching cost (500) and
    links opponents closer than 10 m along the track into one side decision; the MPC is
    solved as one SQP real-time iteration per step with the DCBF imposed at every stage
    (the paper's "at each prediction step", including the first transition), soft track
    and barrier constraints with L1 + L2 slack, and the velocity-aware barrier ellipse
    ``a = a0 + max(0, v - v_i)^2 / (2 a_brake)``. Episodes, the plant and the opponents are
    those of the world, not of the controller.
    """
    if isinstance(name, str):
        key = name.strip().lower()
        if key == "sofar":
            return StackConfig()
        if key == "paper":
            base = StackConfig()
            return dataclasses.replace(base, follow=False, pace_prediction=False, footprint_edges=False,
                                       miqp=dataclasses.replace(base.miqp, closing_decel=0.0))
    raise ValueError(f"unknown stack preset {name!r}; valid presets: {', '.join(STACK_PRESETS)}")


@dataclass(frozen=True)
class StackOutput:
    """Result of one controller step."""

    u: np.ndarray
    """Control (a [m/s^2], delta_dot [rad/s]) to apply now."""
    gamma: float
    """Barrier decay used."""
    mpc: MPCResult
    """The MPC result (prediction, status, slacks, solve time)."""
    plan: PlanResult | None
    """The MIQP plan in force (None with the MIQP off or before the first plan)."""
    miqp_ran: bool
    """Whether the MIQP was solved in this step."""
    opponents_rel: np.ndarray
    """Rows (gap, n, v) of the opponents the planners saw."""
    mpc_time: float
    """Wall time of the MPC solve [s]."""
    miqp_time: float
    """Wall time of the MIQP solve in this step (0 when it did not run) [s]."""
    ego_s: float = 0.0
    """Arc length of the ego at this step [m]: the s of ``mpc.x_pred`` is relative to it."""
    plan_s: float = 0.0
    """Arc length of the ego when ``plan`` was computed [m]: ``plan.s`` is relative to it."""
    following: bool = False
    """Whether the plan in force follows an opponent that cannot be passed."""


class OvertakingStack:
    """MIQP passing-side planner + MPC-DCBF on one track (Algorithm 1)."""

    def __init__(self, track, config: StackConfig | None = None, vehicle: VehicleParams = AV21):
        self.track = track
        self.config = config or StackConfig()
        self.vehicle = vehicle
        self.mpc = MPCDCBF(self.config.mpc, vehicle)
        self.planner = PassingSidePlanner(self.config.miqp)
        self._node_t = np.arange(self.config.miqp.nodes) * self.config.miqp.node_dt
        self._mpc_t = self.config.mpc.time_grid()
        self._mpc_gradient = GridGradient(self._mpc_t) if len(self._mpc_t) > 1 else None
        p = vehicle
        self._reach = max(p.cg_to_front, p.cg_to_rear)
        # footprint samples along the track: rear end, middle, front end
        self._edge_offsets = np.linspace(-p.cg_to_rear, p.cg_to_front, 5)
        # time along two laps at the speed profile, for the pace-ratio prediction of the opponents
        samples = np.asarray(track.s, float)
        L = float(track.length)
        grid = np.concatenate([samples, samples + L, [2.0 * L]])
        v_prof = np.maximum(np.asarray(track.speed(grid), float), 0.1)
        self._pace_s = grid
        self._pace_t = np.concatenate([[0.0], np.cumsum(2.0 * np.diff(grid) / (v_prof[1:] + v_prof[:-1]))])
        self.reset()

    def reset(self) -> None:
        """Forget warm starts, the last plan and the counters."""
        self.mpc.reset()
        self.planner.reset()
        self._plan: PlanResult | None = None
        self._plan_s: float = 0.0
        self._last_plan_call_s: float | None = None
        self._step = 0
        self._follow: tuple | None = None  # (rows (gap, n, v) at plan time, plan step) of followed opponents
        self._follow_calls = 0  # MIQP calls since the pass was last examined while following
        self._last_pred: np.ndarray | None = None  # previous MPC prediction (for the heading error)
        self.counters = {"steps": 0, "mpc_failures": 0, "miqp_failures": 0, "miqp_solves": 0,
                         "follow_steps": 0}

    # ------------------------------------------------------------------ helpers
    def relative_opponents(self, ego_s: float, opponents: np.ndarray) -> np.ndarray:
        """Rows (gap, n, v) of the opponents within the look-behind/look-ahead window, nearest first."""
        opp = np.asarray(opponents, float).reshape(-1, 3)
        if opp.shape[0] == 0:
            return np.zeros((0, 3))
        gap = np.asarray(self.track.gap(opp[:, 0], ego_s), float).reshape(-1)
        keep = (gap >= -self.config.look_behind) & (gap <= self.config.look_ahead)
        rel = opp[keep]  # a copy (boolean indexing)
        rel[:, 0] = gap[keep]
        return rel[np.argsort(np.abs(rel[:, 0]))]

    def predict_opponents(self, ego_s: float, opp_rel: np.ndarray, times: np.ndarray) -> np.ndarray:
        """(M, len(times)) arc lengths of the opponents relative to the ego now [m], at ``times`` [s].

        Each opponent keeps its current pace ratio to the circuit's speed profile,
        ``ds/dt = rho_i v_profile(s)`` with ``rho_i = v_i / v_profile(s_i)``: cars slow down for
        corners, which a constant-speed prediction misses by several metres over a second
        at a corner entry.
        """
        opp_rel = np.asarray(opp_rel, float).reshape(-1, 3)
        times = np.asarray(times, float)
        if opp_rel.shape[0] == 0:
            return np.zeros((0, times.size))
        if not self.config.pace_prediction:
            return opp_rel[:, :1] + opp_rel[:, 2:3] * times[None, :]
        s_abs = np.asarray(self.track.wrap(ego_s + opp_rel[:, 0]), float)
        rho = np.maximum(opp_rel[:, 2], 0.0) / np.maximum(np.asarray(self.track.speed(s_abs), float), 0.1)
        t0 = _interp(s_abs, self._pace_s, self._pace_t)
        s_pred = _interp(t0[:, None] + rho[:, None] * times[None, :], self._pace_t, self._pace_s)
        return opp_rel[:, :1] + (s_pred - s_abs[:, None])

    def _node_positions(self, ego_s: float, ego_v: float) -> np.ndarray:
        """Ego arc length (relative) at the MIQP node times, from the speed reference and the acceleration limits."""
        cfg = self.config
        p = self.vehicle
        dt = cfg.miqp.node_dt
        v0 = max(ego_v, 0.0)
        dv_min, dv_max = p.a_min * dt, p.a_max * dt
        s = v0 * self._node_t  # first guess: constant speed
        for _ in range(2):  # two fixed-point passes: speed reference at the guessed positions
            v_ref = cfg.speed_factor * np.asarray(self.track.speed(ego_s + s), float)
            speeds = []  # a Python list: element-wise numpy writes cost more than the loop itself
            vk = v0
            for vr in v_ref.tolist():  # vk <- clip(vr, vk + dv_min, vk + dv_max), without min/max calls
                speeds.append(vk)
                lower = vk + dv_min
                upper = vk + dv_max
                vk = lower if vr < lower else (upper if vr > upper else vr)
            v = np.array(speeds)
            s = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * dt)])
        return s

    def edges(self, s_abs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(n_min, n_max) at arc lengths ``s_abs`` [m]: with ``footprint_edges`` the narrowest
        within the car's length around each point, else the edges there."""
        s_abs = np.asarray(s_abs, float)
        if not self.config.footprint_edges:
            return (-np.asarray(self.track.width_right(s_abs), float),
                    np.asarray(self.track.width_left(s_abs), float))
        pts = s_abs[:, None] + self._edge_offsets[None, :]
        wr = np.asarray(self.track.width_right(pts.ravel()), float).reshape(pts.shape).min(axis=1)
        wl = np.asarray(self.track.width_left(pts.ravel()), float).reshape(pts.shape).min(axis=1)
        return -wr, wl

    def _braking_positions(self, ego_v: float, decel: float) -> np.ndarray:
        """Ego node positions when braking at ``decel`` [m/s^2] from ``ego_v`` until standstill [m]."""
        v0 = max(ego_v, 0.0)
        tt = np.minimum(self._node_t, v0 / decel)
        return v0 * tt - 0.5 * decel * tt * tt

    def _follow_positions(self, s_nodes: np.ndarray, s_brake: np.ndarray, blocker_s: np.ndarray) -> np.ndarray:
        """Ego node positions that stay ``follow_gap`` behind the blockers (predicted arc lengths
        ``blocker_s`` at the node times), no slower than braking allows."""
        cap = (blocker_s - self.config.follow_gap).min(axis=0)
        return np.maximum.accumulate(np.maximum(s_brake, np.minimum(s_nodes, cap)))

    def _can_stay_behind(self, ego_v: float, gap: np.ndarray, opp_s: np.ndarray) -> np.ndarray:
        """Whether the ego, braking at ``follow_reach_decel``, can stay (or get) behind each opponent.

        ``gap`` [m] are the current gaps (opponent minus ego), ``opp_s`` [m] the predicted
        opponent positions at the node times. With ``follow_alongside`` the gap under hard
        braking must never shrink below ``min(gap, a0)`` and must reach ``a0`` by the end of
        the horizon, so a car the ego is already alongside is followable when braking drops
        the ego behind it. Without it the gap must stay at least ``a0`` throughout.
        """
        a0 = self.config.mpc.barrier.a0
        room = opp_s - self._braking_positions(ego_v, self.config.follow_reach_decel)[None, :]
        if not self.config.follow_alongside:
            return room.min(axis=1) >= a0
        return (room.min(axis=1) >= np.minimum(gap, a0) - 1e-6) & (room[:, -1] >= a0)

    def _plan_lateral(self, ego_s: float, ego_n: float, ego_v: float, opp_rel: np.ndarray) -> float:
        cfg = self.config
        s_nodes = self._node_positions(ego_s, ego_v)
        n_min, n_max = self.edges(ego_s + s_nodes)
        n_ref = np.zeros_like(s_nodes)
        opp_s = self.predict_opponents(ego_s, opp_rel, self._node_t)
        progress = 0.0 if self._last_plan_call_s is None else float(self.track.gap(ego_s, self._last_plan_call_s))
        t0 = time.perf_counter()
        memory = self.planner.memory()
        was_following, self._follow = self._follow, None
        plan = None
        if was_following is not None and self._follow_calls + 1 < cfg.follow_recheck:
            # between two examinations of the pass: re-solve only the follow plan, same followed cars
            blocked = self._followed_rows(ego_s, opp_rel, was_following)
            if blocked is not None and self._can_stay_behind(ego_v, opp_rel[:, 0], opp_s)[blocked].all():
                follow = self._follow_plan(ego_s, ego_n, ego_v, s_nodes, n_ref, opp_rel, opp_s, blocked, progress)
                if follow is not None and follow.max_slack <= cfg.follow_slack:
                    plan = follow
                    self._follow = (opp_rel[blocked].copy(), self._step)
                    self._follow_calls += 1
                else:
                    self.planner.restore_memory(memory)
        if plan is None:
            self._follow_calls = 0
            plan = self.planner.plan(s_nodes, n_ref, n_min, n_max, ego_n, opp_rel, progress=progress,
                                     opponent_s=opp_s)
            if cfg.follow and plan.success and plan.opponent_slack is not None and len(opp_rel):
                # an opponent ahead whose clearance the best passing plan violates, and behind which the
                # ego can stay or drop (_can_stay_behind): follow it
                # hysteresis: while following, a pass is only resumed once it is (nearly) clear
                threshold = cfg.follow_release_slack if was_following is not None else cfg.follow_slack
                blocked = ((plan.opponent_slack > threshold) & (opp_rel[:, 0] > 0.0)
                           & self._can_stay_behind(ego_v, opp_rel[:, 0], opp_s))
                if blocked.any():
                    passing_memory = self.planner.memory()
                    self.planner.restore_memory(memory)
                    follow = self._follow_plan(ego_s, ego_n, ego_v, s_nodes, n_ref, opp_rel, opp_s, blocked,
                                               progress)
                    if follow is not None and follow.max_slack < plan.max_slack:
                        plan = follow
                        self._follow = (opp_rel[blocked].copy(), self._step)
                    else:
                        self.planner.restore_memory(passing_memory)
        elapsed = time.perf_counter() - t0
        self._last_plan_call_s = ego_s
        self.counters["miqp_solves"] += 1
        if not plan.success:
            self.counters["miqp_failures"] += 1
        self._plan = plan
        self._plan_s = ego_s
        return elapsed

    def _follow_plan(self, ego_s: float, ego_n: float, ego_v: float, s_nodes: np.ndarray, n_ref: np.ndarray,
                     opp_rel: np.ndarray, opp_s: np.ndarray, blocked: np.ndarray,
                     progress: float) -> PlanResult | None:
        """The plan that follows the ``blocked`` opponents (None if it fails), sides per input row.

        Followed opponents are kept behind longitudinally (speed cap, barrier), not passed: the
        lateral plan leaves them out, except those the ego is still alongside (less than a0
        behind), whose side it must keep until braking has dropped it behind.
        """
        cfg = self.config
        s_follow = self._follow_positions(s_nodes, self._braking_positions(ego_v, cfg.follow_decel), opp_s[blocked])
        n_min_f, n_max_f = self.edges(ego_s + s_follow)
        planned = ~blocked | (opp_rel[:, 0] < cfg.mpc.barrier.a0)
        plan = self.planner.plan(s_follow, n_ref, n_min_f, n_max_f, ego_n, opp_rel[planned],
                                 progress=progress, opponent_s=opp_s[planned])
        if not plan.success:
            return None
        sides = np.zeros(len(opp_rel), dtype=int)
        sides[planned] = plan.sides
        slack = np.zeros(len(opp_rel))
        slack[planned] = plan.opponent_slack
        return dataclasses.replace(plan, sides=sides, opponent_slack=slack)

    def _followed_rows(self, ego_s: float, opp_rel: np.ndarray, follow: tuple) -> np.ndarray | None:
        """Mask of the rows of ``opp_rel`` that are the followed opponents of ``follow``, matched to
        their predicted positions (within 3 m along and 1.5 m across the track); None when one of
        them is not found (overtaken, respawned, or out of the planners' window)."""
        rows, step0 = follow
        if len(opp_rel) == 0:
            return None
        elapsed = (self._step - step0) * self.config.mpc.control_dt
        pred = (self.predict_opponents(self._plan_s, rows, np.array([elapsed]))[:, 0]
                - float(self.track.gap(ego_s, self._plan_s)))
        dist = ((opp_rel[None, :, 0] - pred[:, None]) / 3.0) ** 2 + ((opp_rel[None, :, 1] - rows[:, 1:2]) / 1.5) ** 2
        nearest = dist.argmin(axis=1)
        if (dist[np.arange(len(rows)), nearest] > 1.0).any():
            return None
        mask = np.zeros(len(opp_rel), dtype=bool)
        mask[nearest] = True
        return mask

    def _heading_error_guess(self) -> np.ndarray | None:
        """|e| along the next MPC horizon from the previous prediction shifted by one period."""
        if self._last_pred is None:
            return None
        t = self._mpc_t
        return np.abs(_interp(t + self.config.mpc.control_dt, t, self._last_pred[:, 2]))

    def stage_data(self, ego_s: float) -> MPCStageData:
        """Per-stage data of the MPC at the s of its warm start."""
        cfg = self.config
        s_rel = np.asarray(self.mpc.predicted_s(), float)
        s_abs = ego_s + s_rel
        if self._plan is not None and cfg.use_miqp:
            shift = float(self.track.gap(ego_s, self._plan_s))
            n_ref = np.asarray(self._plan.lateral_at(s_rel + shift), float)
        else:
            n_ref = np.zeros_like(s_rel)
        v_ref = cfg.speed_factor * np.asarray(self.track.speed(s_abs), float)
        if self._follow is not None and cfg.use_miqp:
            rows, step0 = self._follow
            elapsed = (self._step - step0) * cfg.mpc.control_dt
            t = self._mpc_t
            pred = self.predict_opponents(self._plan_s, rows, elapsed + t)  # relative to the ego at plan time
            gap = pred.T - float(self.track.gap(ego_s, self._plan_s)) - s_rel[:, None]
            v_o = self._mpc_gradient(pred).T if self._mpc_gradient is not None else rows[None, :, 2]
            v_cap2 = v_o ** 2 + 2.0 * cfg.follow_decel * (gap - cfg.follow_gap)
            v_ref = np.minimum(v_ref, np.sqrt(np.maximum(v_cap2.min(axis=1), 0.0)))
        n_min, n_max = self.edges(s_abs)
        if cfg.footprint_edges:
            e_abs = self._heading_error_guess()
            if e_abs is not None:
                swing = self._reach * np.sin(np.minimum(e_abs, 0.5 * math.pi))
                n_min = n_min + swing
                n_max = n_max - swing
        return MPCStageData(
            kappa=np.asarray(self.track.curvature(s_abs), float),
            n_ref=n_ref,
            v_ref=v_ref,
            n_min=n_min,
            n_max=n_max,
        )

    # ------------------------------------------------------------------ step
    def step(self, ego_frenet, opponents, gamma: float) -> StackOutput:
        """One control step.

        ``ego_frenet`` = (s, n, e, v, delta) of the ego; ``opponents`` = rows (s, n, v) with absolute
        arc length [m] and arc-length speed [m/s]; ``gamma`` in (0, 1] the barrier decay.
        """
        gamma = float(gamma)
        if not math.isfinite(gamma) or not (0.0 < gamma <= 1.0):
            raise ValueError(f"gamma must be a finite number in (0, 1], got {gamma!r}")
        s, n, e, v, delta = np.asarray(ego_frenet, float).tolist()
        opp_rel = self.relative_opponents(s, opponents)
        miqp_ran = False
        miqp_time = 0.0
        if self.config.use_miqp and (self._plan is None or self._step % self.config.miqp_interval == 0):
            miqp_time = self._plan_lateral(s, n, v, opp_rel)
            miqp_ran = True
        stage = self.stage_data(s)
        opp_mpc = opp_rel
        if self.config.pace_prediction and len(opp_rel):
            # the MPC predicts opponents at constant speed: give it their mean speed over its horizon
            t_end = float(self._mpc_t[-1])
            s_end = self.predict_opponents(s, opp_rel, np.array([t_end]))[:, 0]
            opp_mpc = opp_rel.copy()
            opp_mpc[:, 2] = (s_end - opp_rel[:, 0]) / t_end
        result = self.mpc.solve(np.array([0.0, n, e, v, delta]), stage, opp_mpc, gamma)
        if not result.success:
            self.counters["mpc_failures"] += 1
        self._last_pred = result.x_pred if result.status == "solved" else None
        following = self._follow is not None and self.config.use_miqp
        self.counters["follow_steps"] += int(following)
        self._step += 1
        self.counters["steps"] += 1
        return StackOutput(
            u=result.u, gamma=gamma, mpc=result, plan=self._plan if self.config.use_miqp else None,
            miqp_ran=miqp_ran, opponents_rel=opp_rel, mpc_time=result.solve_time, miqp_time=miqp_time,
            ego_s=s, plan_s=self._plan_s, following=following,
        )
