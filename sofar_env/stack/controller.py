"""The control step of Algorithm 1: :class:`OvertakingStack` and its :class:`StackOutput`.

One step: the opponents relative to the ego (:mod:`~sofar_env.stack.prediction`), every
``miqp_interval``-th step the passing-side plan or a follow plan
(:mod:`~sofar_env.stack.follow`), the MPC's per-stage references and track bounds
(:mod:`~sofar_env.stack.edges`), and the MPC-DCBF solve with the caller's ``gamma``. Two switches of
:class:`~sofar_env.configs.stack.StackConfig`, off in ``StackConfig()`` and on in the default controller
(preset ``"sofar"``, what ``config=None`` gives), change how a slow car is driven: the
*restart mode* (``restart_lateral_weight``: a second MPC with a lower lateral-tracking weight solves the
steps of a restart from standstill) and the *turned-car creep* (``follow_creep_speed``: a follow cap that
does not stop a car turned to the track).
The stack never raises on numerical trouble: the planners return fallbacks, which are
counted (:attr:`OvertakingStack.counters`).
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass

import numpy as np

from ..control.mpc import MPCDCBF, MPCResult, MPCStageData
from ..control.mpc.ends import EndOffsets
from ..planning.miqp import PassingSidePlanner, PlanResult
from ..vehicle import AV21, VehicleParams
from ..configs.registry import default_stack
from .config import StackConfig
from .edges import TrackEdges
from .follow import PassOrFollow
from .prediction import OpponentPredictor, ego_node_positions, lateral_motion, relative_opponents
from .stage import StageLookup

__all__ = ["StackOutput", "OvertakingStack"]


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
        self.config = config or default_stack()
        self.vehicle = vehicle
        cfg = self.config
        if cfg.reference_numerics is None:
            self.mpc = MPCDCBF(cfg.mpc, vehicle)
        else:  # the bug-compatible controller (stack_preset("reference-numerics"))
            from ..control.refnum import ReferenceNumericsMPC

            rn = cfg.reference_numerics
            self.mpc = ReferenceNumericsMPC(cfg.mpc, rn, vehicle, rn.spacing(getattr(track, "name", None)))
        self.planner = PassingSidePlanner(cfg.miqp)
        self.predict = OpponentPredictor(track, pace_ratio=cfg.pace_prediction)
        self.edges = TrackEdges(track, vehicle, footprint_aware=cfg.footprint_edges)
        self._stage = StageLookup(track, self.edges, cfg.speed_factor)
        self.pass_or_follow = PassOrFollow(cfg, self.planner, track, self.predict, self.edges)
        self._slow_mpc: MPCDCBF | None = None  # the slow end rows' MPC (slow_rows_speed)
        slow = cfg.slow_rows_speed is not None and cfg.reference_numerics is None
        slow_rows = "recoverable-curved" if cfg.slow_rows_curved else "recoverable"
        if slow:
            self._slow_mpc = MPCDCBF(dataclasses.replace(cfg.mpc, track_rows=slow_rows), vehicle)
        self._restart_mpc: MPCDCBF | None = None  # the restart mode's MPC (restart_lateral_weight)
        if cfg.restart_lateral_weight is not None and cfg.reference_numerics is None:
            q = (cfg.mpc.q[0], float(cfg.restart_lateral_weight)) + tuple(cfg.mpc.q[2:])
            rows = slow_rows if slow else cfg.mpc.track_rows
            restart = dataclasses.replace(cfg.mpc, q=q, track_rows=rows, track_buffer=_buffer_width(cfg, vehicle))
            if cfg.restart_buffer_scale is not None:
                restart = dataclasses.replace(restart, track_buffer_slack=tuple(
                    float(cfg.restart_buffer_scale) * w for w in cfg.mpc.track_buffer_slack))
            if cfg.restart_horizon is not None:
                restart = dataclasses.replace(restart, horizon=cfg.restart_horizon)
            if cfg.restart_heading_extent is not None:
                restart = dataclasses.replace(restart, barrier=dataclasses.replace(
                    restart.barrier, heading_extent=cfg.restart_heading_extent))
            self._restart_mpc = MPCDCBF(restart, vehicle)
            self._turn_back_angle = EndOffsets(vehicle, recoverable=True).e_star
        self._node_t = np.arange(cfg.miqp.nodes) * cfg.miqp.node_dt
        self._mpc_t = cfg.mpc.time_grid()
        # the restart mode's time grid; its own only with restart_horizon (then its stage data are its own)
        self._restart_t = self._mpc_t if cfg.restart_horizon is None else self._restart_mpc.config.time_grid()
        self.reset()

    def reset(self) -> None:
        """Forget warm starts, the last plan, the followed opponents and the counters."""
        self.mpc.reset()
        if self._restart_mpc is not None:
            self._restart_mpc.reset()
        if self._slow_mpc is not None:
            self._slow_mpc.reset()
        self._slow = False  # the slow end rows are on (slow_rows_speed)
        self._restarting = False  # in the restart mode (restart_lateral_weight)
        self._creeping = False  # the follow cap keeps the creep speed (follow_creep_speed)
        self.planner.reset()
        self.pass_or_follow.reset()
        self._plan: PlanResult | None = None
        self._plan_s: float = 0.0
        self._last_plan_call_s: float | None = None
        self._step = 0
        self._last_pred: np.ndarray | None = None  # previous MPC prediction (for the heading error)
        self.counters = {"steps": 0, "mpc_failures": 0, "miqp_failures": 0, "miqp_solves": 0,
                         "follow_steps": 0, "parked_checks": 0, "parked_passes": 0, "mpc_restarts": 0,
                         "mpc_restarts_taken": 0, "slow_restarts": 0, "creep_steps": 0, "slow_rows_steps": 0,
                         "qp_fallbacks": 0}
        """Episode counters: control steps, MPC / MIQP failures, MIQP solves, steps in follow mode,
        MIQP calls that tried / took a pass of near-stationary opponents (:mod:`~sofar_env.stack.follow`),
        MPC restarts from a cold guess tried / kept (``mpc.restart_slack``), restart modes entered
        (``restart_lateral_weight``), steps with the creep floor on the follow cap (``follow_creep_speed``), steps
        under the slow end rows (``slow_rows_speed``), QPs solved by the fallback backend (``mpc.qp_fallback``)."""

    @property
    def mpcs(self) -> tuple:
        """Every MPC of the stack: its own, then the slow end rows' and the restart mode's where configured."""
        return tuple(m for m in (self.mpc, self._slow_mpc, self._restart_mpc) if m is not None)

    @property
    def mpc_in_force(self):
        """The MPC that solved the last step (the stack's own before the first)."""
        return self._restart_mpc if self._restarting else self._own_mpc

    @property
    def plan_times(self) -> np.ndarray:
        """(N+1,) times [s] of the stages of the last step's plan (``StackOutput.mpc.x_pred``): the MPC's time grid,
        or the restart mode's with ``restart_horizon`` (the stack's own array: not to be written to)."""
        return self._restart_t if self._restarting else self._mpc_t

    @property
    def _own_mpc(self) -> MPCDCBF:
        """The stack's MPC at this speed: the slow end rows' below ``slow_rows_speed``, else its own."""
        return self._slow_mpc if self._slow else self.mpc

    @property
    def following(self) -> bool:
        """Whether the plan in force follows an opponent that cannot be passed."""
        return self.pass_or_follow.target is not None and self.config.use_miqp

    def _plan_lateral(self, ego_s: float, ego_n: float, ego_v: float, opp_rel: np.ndarray) -> float:
        """Solve the MIQP (pass or follow) at the ego's (s, n, v); returns its wall time [s]."""
        cfg = self.config
        s_nodes = ego_node_positions(self.track, ego_s, ego_v, self._node_t, cfg.miqp.node_dt,
                                     cfg.speed_factor, self.vehicle)
        opp_s = self.predict(ego_s, opp_rel, self._node_t)
        progress = 0.0 if self._last_plan_call_s is None else float(self.track.gap(ego_s, self._last_plan_call_s))
        t0 = time.perf_counter()
        plan = self.pass_or_follow.plan(ego_s, ego_n, ego_v, s_nodes, opp_rel, opp_s, progress, self._step)
        elapsed = time.perf_counter() - t0
        self._last_plan_call_s = ego_s
        self.counters["miqp_solves"] += 1
        if not plan.success:
            self.counters["miqp_failures"] += 1
        self.counters["parked_checks"] = self.pass_or_follow.checks
        self.counters["parked_passes"] = self.pass_or_follow.passes
        self._plan = plan
        self._plan_s = ego_s
        return elapsed

    def stage_data(self, ego_s: float, mpc: MPCDCBF | None = None) -> MPCStageData:
        """Per-stage data of the MPC at the s of its warm start (:class:`~sofar_env.stack.stage.StageLookup`):
        the stack's own at this speed, or ``mpc`` on its own time grid (the restart mode's with
        ``restart_horizon``)."""
        cfg = self.config
        s_rel = (self._own_mpc if mpc is None else mpc).predicted_s()
        t = self._mpc_t if mpc is None else mpc.config.time_grid()
        s_abs, kappa, v_ref, n_min, n_max = self._stage(ego_s, s_rel)
        if self._plan is not None and cfg.use_miqp:
            shift = float(self.track.gap(ego_s, self._plan_s))
            n_ref = np.asarray(self._plan.lateral_at(s_rel + shift), float)
        else:
            n_ref = np.zeros_like(s_rel)
        if cfg.use_miqp:
            creep = cfg.follow_creep_speed if self._creeping else 0.0
            cap = self.pass_or_follow.speed_cap(ego_s, s_rel, t, self._step, creep=creep)
            if cap is not None:
                v_ref = np.minimum(v_ref, cap)
        # an MPC that bounds the car's ends itself gets the edges without the frozen-heading tightening
        x_prev = self._last_pred if cfg.mpc.track_rows == "reference" and not self._slow else None
        if x_prev is not None and len(x_prev) != len(t):  # a plan of the other horizon (restart_horizon)
            x_prev = None
        n_min, n_max = self.edges.for_mpc(s_abs, x_prev, t, cfg.mpc.control_dt,
                                          edge_relative=cfg.use_miqp and self.pass_or_follow.parked_plan,
                                          edges=(n_min, n_max))
        return MPCStageData(kappa=kappa, n_ref=n_ref, v_ref=v_ref, n_min=n_min, n_max=n_max)

    def step(self, ego_frenet, opponents, gamma: float) -> StackOutput:
        """One control step.

        ``ego_frenet`` = (s, n, e, v, delta) of the ego; ``opponents`` = rows (s, n, v) with absolute
        arc length [m] and arc-length speed [m/s], optionally with a fourth column, the lateral rate
        n_dot [m/s] (used with ``lateral_prediction``); ``gamma`` in (0, 1] the barrier decay.
        """
        gamma = float(gamma)
        if not math.isfinite(gamma) or not (0.0 < gamma <= 1.0):
            raise ValueError(f"gamma must be a finite number in (0, 1], got {gamma!r}")
        cfg = self.config
        s, n, e, v, delta = np.asarray(ego_frenet, float).tolist()
        opp_rel = relative_opponents(self.track, s, opponents, cfg.look_behind, cfg.look_ahead)
        lateral_rate = None
        if opp_rel.shape[1] == 4:
            if cfg.lateral_prediction and len(opp_rel):
                # the planners see each car where its lateral move ends; the MPC gets the move itself
                n_end, lateral_rate = lateral_motion(self.track, s, opp_rel, cfg.lateral_prediction_time,
                                                     cfg.lateral_rate_deadband, 0.5 * self.vehicle.width)
                n_now = opp_rel[:, 1]
                opp_rel = opp_rel[:, :3].copy()
                if cfg.lateral_prediction_plan:
                    opp_rel[:, 1] = n_end
            else:
                opp_rel = opp_rel[:, :3]
        miqp_ran = False
        miqp_time = 0.0
        if cfg.use_miqp and (self._plan is None or self._step % cfg.miqp_interval == 0):
            miqp_time = self._plan_lateral(s, n, v, opp_rel)
            miqp_ran = True
        if cfg.follow_creep_speed > 0.0:
            self._creeping = self._creep(e)
            self.counters["creep_steps"] += int(self._creeping)
        if self._slow_mpc is not None:
            self._slow_rows(v)
        stage = self.stage_data(s)
        mpc = self._select_mpc(v, stage)
        grid = self.plan_times
        if grid is not self._mpc_t:
            stage = self.stage_data(s, mpc)
        opp_mpc = opp_rel
        if cfg.pace_prediction and len(opp_rel):
            # the MPC predicts opponents at constant speed: give it their mean speed over its horizon
            t_end = float(grid[-1])
            s_end = self.predict(s, opp_rel, np.array([t_end]))[:, 0]
            opp_mpc = opp_rel.copy()
            opp_mpc[:, 2] = (s_end - opp_rel[:, 0]) / t_end
        if lateral_rate is not None:
            # the MPC (constant lateral rate) gets the sensed offset and the mean rate over its horizon
            t_end = float(grid[-1])
            rate = lateral_rate * (min(t_end, cfg.lateral_prediction_time) / t_end)
            opp_mpc = np.column_stack([opp_mpc[:, 0], n_now, opp_mpc[:, 2], rate])
        if cfg.reference_numerics is not None:  # its slots are filled from every opponent on the track
            half = 0.5 * float(self.track.length)
            opp_mpc = relative_opponents(self.track, s, opponents, half, half)[:, :3]
        x0 = np.array([0.0, n, e, v, delta])
        result = mpc.solve(x0, stage, opp_mpc, gamma)
        if self._restarting:
            result = self._steer_to_lock(result, x0)
        if not result.success:
            self.counters["mpc_failures"] += 1
        self.counters["qp_fallbacks"] += result.qp_fallbacks
        self.counters["mpc_restarts"] = self.mpc.n_restarts
        self.counters["mpc_restarts_taken"] = self.mpc.n_restarts_taken
        self._last_pred = result.x_pred if result.status == "solved" else None
        following = self.following
        self.counters["follow_steps"] += int(following)
        self._step += 1
        self.counters["steps"] += 1
        return StackOutput(
            u=result.u, gamma=gamma, mpc=result, plan=self._plan if cfg.use_miqp else None,
            miqp_ran=miqp_ran, opponents_rel=opp_rel, mpc_time=result.solve_time, miqp_time=miqp_time,
            ego_s=s, plan_s=self._plan_s, following=following,
        )

    def _creep(self, e: float) -> bool:
        """Whether the follow cap keeps the creep speed at this step: a car is followed and the ego is turned by
        more than ``follow_creep_angle``, or it was creeping and is still turned by ``follow_creep_release`` or
        more."""
        cfg = self.config
        if not self.following:
            return False
        if abs(e) > cfg.follow_creep_angle:
            return True
        return self._creeping and abs(e) >= cfg.follow_creep_release

    def _slow_rows(self, v: float) -> None:
        """Switch the slow end rows on below ``slow_rows_speed`` and off from ``slow_rows_exit_speed``; the MPC that
        takes over starts cold."""
        cfg = self.config
        slow = v < cfg.slow_rows_speed or (self._slow and v < cfg.slow_rows_exit_speed)
        if slow != self._slow:
            (self._slow_mpc if slow else self.mpc).reset()
        self._slow = slow
        self.counters["slow_rows_steps"] += int(slow)

    def _select_mpc(self, v: float, stage: MPCStageData) -> MPCDCBF:
        """The MPC that solves this step at speed ``v`` [m/s] under the own MPC's ``stage`` data: the stack's MPC,
        or in the restart mode (``restart_lateral_weight``) the second MPC, whose plan then steers towards full
        lock while it stays below ``restart_speed`` with the car turned by ``e*`` or more
        (:class:`~sofar_env.configs.stack.StackConfig`). Enters and leaves the mode (a cold start of the MPC that
        takes over)."""
        own = self._own_mpc
        spare = self._restart_mpc
        if spare is None:
            return own
        cfg = self.config
        free = float(np.max(stage.v_ref)) >= cfg.restart_speed
        if free and (v < cfg.restart_speed or (self._restarting and v < cfg.restart_exit_speed)):
            if not self._restarting:
                spare.reset()
                self.counters["slow_restarts"] += 1
            self._restarting = True
            return spare
        if self._restarting:  # back to the stack's own MPC, from a cold start
            self._restarting = False
            own.reset()
        return own

    def _steer_to_lock(self, result: MPCResult, x0: np.ndarray) -> MPCResult:
        """``result`` with its steering rate replaced by one towards full lock on the side that turns the car back,
        at the rate limit, when its plan stays below ``restart_speed`` and ``|e| >= e*``; else ``result``."""
        e, delta = float(x0[2]), float(x0[4])
        if float(result.x_pred[1, 3]) >= self.config.restart_speed or abs(e) < self._turn_back_angle:
            return result
        veh = self.vehicle
        lock = -math.copysign(veh.steer_max, e)
        if abs(lock - delta) < 1e-3:
            return result
        dt = max(self.config.mpc.control_dt, 1e-9)
        rate = float(np.clip((lock - delta) / dt, -veh.steer_rate_max, veh.steer_rate_max))
        return dataclasses.replace(result, u=np.array([float(result.u[0]), rate]))


def _buffer_width(cfg: StackConfig, vehicle: VehicleParams) -> float:
    """``mpc.track_buffer`` of the restart mode's MPC [m]: the band of the track margin in which the car's side is
    more than ``restart_buffer_edge`` from the edge (0 with the option off or where the margin leaves none)."""
    if cfg.restart_buffer_edge is None:
        return 0.0
    return max(cfg.mpc.track_margin - 0.5 * vehicle.width - cfg.restart_buffer_edge, 0.0)
