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

The stack never raises on numerical trouble: the planners return fallbacks,
which are counted (:attr:`OvertakingStack.counters`).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from .control.mpc import MPCConfig, MPCDCBF, MPCResult, MPCStageData
from .planning.miqp import MIQPConfig, PassingSidePlanner, PlanResult
from .vehicle import AV21, VehicleParams

__all__ = ["StackConfig", "StackOutput", "OvertakingStack"]


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
    mpc: MPCConfig = field(default_factory=MPCConfig)
    """The low-level MPC-DCBF."""
    miqp: MIQPConfig = field(default_factory=MIQPConfig)
    """The passing-side planner."""

    def __post_init__(self) -> None:
        if not (0.0 < self.speed_factor <= 1.5):
            raise ValueError(f"speed_factor must lie in (0, 1.5], got {self.speed_factor}")
        if self.miqp_interval < 1:
            raise ValueError("miqp_interval must be >= 1")


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


class OvertakingStack:
    """MIQP passing-side planner + MPC-DCBF on one track (Algorithm 1)."""

    def __init__(self, track, config: StackConfig | None = None, vehicle: VehicleParams = AV21):
        self.track = track
        self.config = config or StackConfig()
        self.vehicle = vehicle
        self.mpc = MPCDCBF(self.config.mpc, vehicle)
        self.planner = PassingSidePlanner(self.config.miqp)
        self._node_t = np.arange(self.config.miqp.nodes) * self.config.miqp.node_dt
        self.reset()

    def reset(self) -> None:
        """Forget warm starts, the last plan and the counters."""
        self.mpc.reset()
        self.planner.reset()
        self._plan: PlanResult | None = None
        self._plan_s: float = 0.0
        self._last_plan_call_s: float | None = None
        self._step = 0
        self.counters = {"steps": 0, "mpc_failures": 0, "miqp_failures": 0, "miqp_solves": 0}

    # ------------------------------------------------------------------ helpers
    def relative_opponents(self, ego_s: float, opponents: np.ndarray) -> np.ndarray:
        """Rows (gap, n, v) of the opponents within the look-behind/look-ahead window, nearest first."""
        opp = np.asarray(opponents, float).reshape(-1, 3)
        if opp.shape[0] == 0:
            return np.zeros((0, 3))
        gap = np.asarray(self.track.gap(opp[:, 0], ego_s), float).reshape(-1)
        keep = (gap >= -self.config.look_behind) & (gap <= self.config.look_ahead)
        rel = np.column_stack([gap, opp[:, 1], opp[:, 2]])[keep]
        return rel[np.argsort(np.abs(rel[:, 0]))]

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
            for vr in v_ref.tolist():
                speeds.append(vk)
                vk = min(max(vr, vk + dv_min), vk + dv_max)
            v = np.array(speeds)
            s = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * dt)])
        return s

    def _plan_lateral(self, ego_s: float, ego_n: float, ego_v: float, opp_rel: np.ndarray) -> float:
        s_nodes = self._node_positions(ego_s, ego_v)
        s_abs = ego_s + s_nodes
        n_min = -np.asarray(self.track.width_right(s_abs), float)
        n_max = np.asarray(self.track.width_left(s_abs), float)
        progress = 0.0 if self._last_plan_call_s is None else float(self.track.gap(ego_s, self._last_plan_call_s))
        t0 = time.perf_counter()
        plan = self.planner.plan(s_nodes, np.zeros_like(s_nodes), n_min, n_max, ego_n, opp_rel, progress=progress)
        elapsed = time.perf_counter() - t0
        self._last_plan_call_s = ego_s
        self.counters["miqp_solves"] += 1
        if not plan.success:
            self.counters["miqp_failures"] += 1
        self._plan = plan
        self._plan_s = ego_s
        return elapsed

    def stage_data(self, ego_s: float) -> MPCStageData:
        """Per-stage data of the MPC at the s of its warm start."""
        s_rel = np.asarray(self.mpc.predicted_s(), float)
        s_abs = ego_s + s_rel
        if self._plan is not None and self.config.use_miqp:
            shift = float(self.track.gap(ego_s, self._plan_s))
            n_ref = np.asarray(self._plan.lateral_at(s_rel + shift), float)
        else:
            n_ref = np.zeros_like(s_rel)
        return MPCStageData(
            kappa=np.asarray(self.track.curvature(s_abs), float),
            n_ref=n_ref,
            v_ref=self.config.speed_factor * np.asarray(self.track.speed(s_abs), float),
            n_min=-np.asarray(self.track.width_right(s_abs), float),
            n_max=np.asarray(self.track.width_left(s_abs), float),
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
        s, n, e, v, delta = (float(x) for x in ego_frenet)
        opp_rel = self.relative_opponents(s, opponents)
        miqp_ran = False
        miqp_time = 0.0
        if self.config.use_miqp and (self._plan is None or self._step % self.config.miqp_interval == 0):
            miqp_time = self._plan_lateral(s, n, v, opp_rel)
            miqp_ran = True
        stage = self.stage_data(s)
        result = self.mpc.solve(np.array([0.0, n, e, v, delta]), stage, opp_rel, gamma)
        if not result.success:
            self.counters["mpc_failures"] += 1
        self._step += 1
        self.counters["steps"] += 1
        return StackOutput(
            u=result.u, gamma=gamma, mpc=result, plan=self._plan if self.config.use_miqp else None,
            miqp_ran=miqp_ran, opponents_rel=opp_rel, mpc_time=result.solve_time, miqp_time=miqp_time,
            ego_s=s, plan_s=self._plan_s,
        )
