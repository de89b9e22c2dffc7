"""Pass or follow: the passing-side MIQP, and following an opponent that cannot be passed.

An addition to the paper's algorithm. The MIQP plans lateral offsets only, with the
ego's progress taken from its speed reference. When no passing side of an opponent
ahead is clear (the plan violates that opponent's clearance by more than
``follow_slack``, e.g. the raceline runs to the edge on the passing side at the next
corner, or the track is too narrow), attempting the pass ends alongside the opponent
with the corridor closing. The stack then *follows* instead: it re-plans with the ego's
node positions held ``follow_gap`` behind the blocking opponent(s) (no slower than
braking at ``follow_decel`` allows) and caps the MPC speed reference at
``sqrt(v_o^2 + 2 follow_decel (gap - follow_gap))``, the speed from which braking at
``follow_decel`` ends at the opponent's speed ``follow_gap`` behind it.

* An opponent behind which the ego can no longer stay (braking at ``follow_reach_decel``
  the gap would shrink below ``min(gap, a0)``, or not reach the barrier's ``a0`` within
  the horizon) is not followed.
* A car the ego is already alongside is followed when braking drops the ego behind it
  (the follow plan keeps the ego's side of it until the ego is ``a0`` behind): holding
  such a pass is what squeezes the ego between that car and a closing edge at a corner
  entry.
* With ``follow_queue``, a nearer car that the follow plan would pass with its clearance violated
  by more than ``follow_slack`` is followed too, when the ego can stay behind it (else the follow
  plan is no better than the pass, and the pass is held into the corner the queue takes).
* While following, the pass is re-examined at every ``follow_recheck``-th MIQP call (in
  between only the follow plan is re-solved), with hysteresis: a pass is resumed only
  once its clearance violation has fallen to ``follow_release_slack``.

* A near-stationary opponent (slower than ``parked_speed``: parked, crashed, crawling) is not
  followed while there is room beside it: when every opponent the passing plan has to clear
  is near-stationary, the pass is re-planned with a side-constraint window shaped like the
  MPC's barrier ellipse (lateral semi-axis ``parked_clearance``, longitudinal ``parked_window``
  plus the braking distance of the closing speed on the approach) instead of the box
  ``safe_lat`` over ``safe_lon``, and the pass-or-follow decision is made on that plan: a car
  is followed only if the plan, sampled between its nodes, enters the barrier's own ellipse
  around it (:func:`~sofar_env.planning.clearance.ellipse_violation`). While such a plan is in
  force (:attr:`PassOrFollow.parked_plan`) the MPC measures the swing of the car's ends against
  the edges' directions, so that it can drive along an edge that converges on the raceline
  (:meth:`~sofar_env.stack.edges.TrackEdges.for_mpc`). When the plan enters the ellipse of a
  car the ego can no longer stop behind (the pass is held), the nearest car beyond it that the
  ego can stop behind is followed, so that a side switch between two close parked cars is made
  at a speed at which it fits. Following such a car would stop the ego behind it for good; a
  car that moves does not need this (its pace is at least 0.1 x the speed profile in Table I).
  Counted in ``checks`` and ``passes``.

With ``follow=False`` (the paper's algorithm) every call plans a pass of every opponent.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from .._gradient import GridGradient
from .._jit import kernel, minimum
from ..planning.clearance import ellipse_violation
from ..planning.miqp import PassingSidePlanner, PlanResult
from .config import StackConfig
from .edges import TrackEdges
from .prediction import OpponentPredictor, braking_positions

__all__ = ["FollowTarget", "PassOrFollow"]


@dataclass(frozen=True, eq=False)
class FollowTarget:
    """The opponents followed by the plan in force."""

    rows: np.ndarray
    """Rows (gap, n, v) of the followed opponents when the plan was made, relative to the ego then."""
    ego_s: float
    """Arc length of the ego when the plan was made [m]."""
    step: int
    """Control step at which the plan was made."""
    parked: bool = False
    """Whether the plan was made with the parked clearance (every opponent it clears near-stationary)."""


class PassOrFollow:
    """Solves the passing-side MIQP and decides between passing and following (module docstring).

    ``target`` is the :class:`FollowTarget` of the plan last returned (None: a passing plan).
    """

    def __init__(self, config: StackConfig, planner: PassingSidePlanner, track, predict: OpponentPredictor,
                 edges: TrackEdges):
        self.config = config
        self.planner = planner
        self.track = track
        self.predict = predict
        self.edges = edges
        self._node_t = np.arange(config.miqp.nodes) * config.miqp.node_dt
        self._time_gradient: tuple[bytes, GridGradient] | None = None  # d/dt on the grid of speed_cap
        self._parked_planner = (PassingSidePlanner(dataclasses.replace(
            config.miqp, safe_lat=config.parked_clearance, safe_lon=config.parked_window,
            window_shape="ellipse"))
                                if config.follow and config.parked_pass else None)
        self.reset()

    def reset(self) -> None:
        """Forget the followed opponents."""
        self.target: FollowTarget | None = None
        self.parked_plan = False
        """Whether the plan last returned was made with the parked clearance (a pass of near-stationary
        opponents, or a follow plan that passes some): the MPC then measures the swing of the car's ends
        against the track edges' directions (:meth:`~sofar_env.stack.edges.TrackEdges.for_mpc`)."""
        self._calls = 0  # MIQP calls since the pass was last examined while following
        self.checks = 0
        """MIQP calls that decided with the parked clearance (every opponent to clear near-stationary)."""
        self.passes = 0
        """Of those, the calls whose plan is a pass (not a follow plan)."""
        if self._parked_planner is not None:
            self._parked_planner.reset()

    def plan(self, ego_s: float, ego_n: float, ego_v: float, s_nodes: np.ndarray, opp_rel: np.ndarray,
             opp_s: np.ndarray, progress: float, step: int) -> PlanResult:
        """The plan of this control step ``step``: a pass, or (``target`` set) a follow plan.

        ``s_nodes`` [m] are the ego's node positions and ``opp_s`` [m] the predicted opponents
        ``opp_rel`` at the node times, relative to the ego at ``ego_s``; ``progress`` [m] is how far
        the ego has advanced since the previous call (for the planner's warm start).
        """
        cfg = self.config
        n_min, n_max = self.edges(ego_s + s_nodes)
        n_ref = np.zeros_like(s_nodes)
        memory = self.planner.memory()
        was_following, self.target = self.target, None
        self.parked_plan = False
        plan = None
        if was_following is not None and self._calls + 1 < cfg.follow_recheck:
            # between two examinations of the pass: re-solve only the follow plan, same followed cars
            blocked = self._followed_rows(ego_s, opp_rel, was_following, step)
            if blocked is not None and self.can_stay_behind(ego_v, opp_rel[:, 0], opp_s)[blocked].all():
                planner = self._parked_planner if was_following.parked else self.planner
                follow = self._follow_plan(ego_s, ego_n, ego_v, s_nodes, n_ref, opp_rel, opp_s, blocked, progress,
                                           planner)
                if follow is not None and was_following.parked:
                    planned = ~blocked | (opp_rel[:, 0] < cfg.mpc.barrier.a0)
                    clear = bool((self._ellipse_violation(follow, opp_rel, opp_s)[planned] <= 0.0).all())
                else:
                    clear = follow is not None and follow.max_slack <= cfg.follow_slack
                if (clear
                        and (not was_following.parked or self._all_parked(opp_rel, (follow.sides != 0) | blocked))):
                    plan = follow
                    self.target = FollowTarget(opp_rel[blocked].copy(), ego_s, step, was_following.parked)
                    self.parked_plan = was_following.parked
                    self._calls += 1
                    if was_following.parked:
                        self.planner.restore_memory(planner.memory())
                else:
                    self.planner.restore_memory(memory)
        if plan is None:
            self._calls = 0
            plan = self.planner.plan(s_nodes, n_ref, n_min, n_max, ego_n, opp_rel, progress=progress,
                                     opponent_s=opp_s)
            if cfg.follow and plan.success and plan.opponent_slack is not None and len(opp_rel):
                # an opponent ahead whose clearance the best passing plan violates, and behind which the
                # ego can stay or drop (can_stay_behind): follow it
                # hysteresis: while following, a pass is only resumed once it is (nearly) clear
                threshold = cfg.follow_release_slack if was_following is not None else cfg.follow_slack
                followable = (opp_rel[:, 0] > 0.0) & self.can_stay_behind(ego_v, opp_rel[:, 0], opp_s)
                blocked = (plan.opponent_slack > threshold) & followable
                planner = self.planner
                constrained = plan.sides != 0
                if self._parked_planner is not None and constrained.any() and self._all_parked(opp_rel, constrained):
                    # every opponent the plan must clear is near-stationary: decide with the parked clearance
                    self.checks += 1
                    passing_memory = self.planner.memory()
                    self._parked_planner.restore_memory(memory)
                    parked = self._parked_planner.plan(s_nodes, n_ref, n_min, n_max, ego_n, opp_rel,
                                                       progress=progress, opponent_s=opp_s)
                    if parked.success and parked.opponent_slack is not None:
                        plan, planner = parked, self._parked_planner
                        blocked = self._parked_blocked(parked, ego_v, opp_rel, opp_s)
                    else:
                        self.planner.restore_memory(passing_memory)
                if blocked.any():
                    passing_memory = planner.memory()
                    planner.restore_memory(memory)
                    follow = self._follow_plan(ego_s, ego_n, ego_v, s_nodes, n_ref, opp_rel, opp_s, blocked,
                                               progress, planner)
                    if cfg.follow_queue and planner is self.planner:
                        follow, blocked = self._follow_queue(follow, blocked, followable, memory, ego_s, ego_n,
                                                             ego_v, s_nodes, n_ref, opp_rel, opp_s, progress)
                    if follow is not None and follow.max_slack < plan.max_slack:
                        plan = follow
                        self.target = FollowTarget(opp_rel[blocked].copy(), ego_s, step,
                                                   planner is not self.planner)
                    else:
                        planner.restore_memory(passing_memory)
                if planner is not self.planner:
                    self.planner.restore_memory(planner.memory())  # the plan in force, for the next call
                    self.passes += int(self.target is None)
                    self.parked_plan = True
        return plan

    def _follow_queue(self, follow: PlanResult | None, blocked: np.ndarray, followable: np.ndarray, memory,
                      ego_s: float, ego_n: float, ego_v: float, s_nodes: np.ndarray, n_ref: np.ndarray,
                      opp_rel: np.ndarray, opp_s: np.ndarray, progress: float) -> tuple[PlanResult | None, np.ndarray]:
        """``StackConfig.follow_queue``: the follow plan ``follow`` of the ``blocked`` opponents, extended to every car
        of ``followable`` (ahead, and the ego can stay behind it) that the plan passes with its clearance violated by
        more than ``follow_slack``, re-solved (from the planner's ``memory`` of before this step) until it violates no
        such car or one fails. Returns the last follow plan (None if it failed) and the followed opponents."""
        while follow is not None:
            nearer = followable & ~blocked & (follow.opponent_slack > self.config.follow_slack)
            if not nearer.any():
                break
            blocked = blocked | nearer
            self.planner.restore_memory(memory)
            follow = self._follow_plan(ego_s, ego_n, ego_v, s_nodes, n_ref, opp_rel, opp_s, blocked, progress,
                                       self.planner)
        return follow, blocked

    def _parked_blocked(self, plan: PlanResult, ego_v: float, opp_rel: np.ndarray,
                        opp_s: np.ndarray) -> np.ndarray:
        """The near-stationary opponents to follow given ``plan``, the plan with the parked clearance.

        Those ahead the plan enters the barrier ellipse of and behind which the ego can stay. When the
        plan enters the ellipse of a car the ego can no longer stay behind (its pass is held), the
        nearest car beyond it that the ego can stay behind is followed too: the room the plan lacks may
        be what a side switch to that car takes at this speed, and the follow plan passes the held car
        alone while slowing down.
        """
        ahead = opp_rel[:, 0] > 0.0
        violated = (self._ellipse_violation(plan, opp_rel, opp_s) > 0.0) & ahead
        followable = self.can_stay_behind(ego_v, opp_rel[:, 0], opp_s) & ahead
        blocked = violated & followable
        held = violated & ~followable
        if held.any():
            beyond = followable & (opp_rel[:, 0] > opp_rel[held, 0].min())
            if beyond.any():
                blocked[np.flatnonzero(beyond)[np.argmin(opp_rel[beyond, 0])]] = True
        return blocked

    def _ellipse_violation(self, plan: PlanResult, opp_rel: np.ndarray, opp_s: np.ndarray) -> np.ndarray:
        """(M,) how far [m] ``plan`` enters the MPC's barrier ellipse of each opponent, laterally
        (:func:`~sofar_env.planning.clearance.ellipse_violation`)."""
        p = self.config.mpc.barrier
        return ellipse_violation(self._node_t, plan.s, plan.d, opp_s, opp_rel[:, 1], p.a0, p.b, p.a_brake)

    def _all_parked(self, opp_rel: np.ndarray, rows: np.ndarray) -> bool:
        """Whether every opponent of ``rows`` (a mask of ``opp_rel``) is slower than ``parked_speed``."""
        return bool((opp_rel[np.asarray(rows, bool), 2] < self.config.parked_speed).all())

    def can_stay_behind(self, ego_v: float, gap: np.ndarray, opp_s: np.ndarray) -> np.ndarray:
        """Whether the ego, braking at ``follow_reach_decel``, can stay (or get) behind each opponent.

        ``gap`` [m] are the current gaps (opponent minus ego), ``opp_s`` [m] the predicted
        opponent positions at the node times. With ``follow_alongside`` the gap under hard
        braking must never shrink below ``min(gap, a0)`` and must reach ``a0`` by the end of
        the horizon, so a car the ego is already alongside is followable when braking drops
        the ego behind it. Without it the gap must stay at least ``a0`` throughout.
        """
        return _stay_behind(self._node_t, float(ego_v), float(self.config.follow_reach_decel),
                            np.asarray(gap, float), np.asarray(opp_s, float), float(self.config.mpc.barrier.a0),
                            bool(self.config.follow_alongside))

    def speed_cap(self, ego_s: float, s_rel: np.ndarray, t: np.ndarray, step: int,
                  creep: float = 0.0) -> np.ndarray | None:
        """Cap [m/s] on the MPC speed reference at the times ``t`` [s] of control step ``step``
        (ego at ``ego_s`` now, at ``s_rel`` [m] relative to that along the horizon): the speed from
        which braking at ``follow_decel`` ends at each followed car's speed ``follow_gap`` behind
        it (``parked_follow_gap`` behind a car slower than ``parked_speed``, where set). ``creep`` > 0:
        the cap is at least ``creep`` at the stages where every followed car is more than the barrier's
        ``a0`` ahead (``StackConfig.follow_creep_speed``). None when no car is followed."""
        if self.target is None:
            return None
        cfg = self.config
        rows, plan_s = self.target.rows, self.target.ego_s
        elapsed = (step - self.target.step) * cfg.mpc.control_dt
        pred = self.predict(plan_s, rows, elapsed + t)  # relative to the ego at plan time
        gap = pred.T - float(self.track.gap(ego_s, plan_s)) - s_rel[:, None]
        v_o = self._gradient(t, pred).T if len(t) > 1 else rows[None, :, 2]
        keep = cfg.follow_gap
        if cfg.parked_follow_gap is not None:
            keep = np.where(np.abs(v_o) < cfg.parked_speed, cfg.parked_follow_gap, cfg.follow_gap)
        v_cap2 = v_o ** 2 + 2.0 * cfg.follow_decel * (gap - keep)
        cap = np.sqrt(np.maximum(v_cap2.min(axis=1), 0.0))
        if creep > 0.0:
            cap = np.where(gap.min(axis=1) > cfg.mpc.barrier.a0, np.maximum(cap, creep), cap)
        return cap

    def _gradient(self, t: np.ndarray, f: np.ndarray) -> np.ndarray:
        """``np.gradient(f, t, axis=1)`` (bit-identical), its coefficients kept for the last grid ``t``
        (recognised by its bytes: cheaper than ``np.array_equal``, and an equal grid is the same grid)."""
        t = np.asarray(t, dtype=float)
        key = t.tobytes()
        cached = self._time_gradient
        if cached is None or cached[0] != key:
            cached = self._time_gradient = (key, GridGradient(t.copy()))
        return cached[1](f)

    def _follow_plan(self, ego_s: float, ego_n: float, ego_v: float, s_nodes: np.ndarray, n_ref: np.ndarray,
                     opp_rel: np.ndarray, opp_s: np.ndarray, blocked: np.ndarray,
                     progress: float, planner: PassingSidePlanner) -> PlanResult | None:
        """The plan that follows the ``blocked`` opponents (None if it fails), sides per input row.

        Followed opponents are kept behind longitudinally (speed cap, barrier), not passed: the
        lateral plan leaves them out, except those the ego is still alongside (less than a0
        behind), whose side it must keep until braking has dropped it behind. The ego's node
        positions stay ``follow_gap`` behind the followed cars, no slower than braking at
        ``follow_decel`` allows.
        """
        cfg = self.config
        s_brake = braking_positions(self._node_t, ego_v, cfg.follow_decel)
        cap = (opp_s[blocked] - cfg.follow_gap).min(axis=0)
        s_follow = np.maximum.accumulate(np.maximum(s_brake, np.minimum(s_nodes, cap)))
        n_min_f, n_max_f = self.edges(ego_s + s_follow)
        planned = ~blocked | (opp_rel[:, 0] < cfg.mpc.barrier.a0)
        plan = planner.plan(s_follow, n_ref, n_min_f, n_max_f, ego_n, opp_rel[planned],
                            progress=progress, opponent_s=opp_s[planned])
        if not plan.success:
            return None
        sides = np.zeros(len(opp_rel), dtype=int)
        sides[planned] = plan.sides
        slack = np.zeros(len(opp_rel))
        slack[planned] = plan.opponent_slack
        return dataclasses.replace(plan, sides=sides, opponent_slack=slack)

    def _followed_rows(self, ego_s: float, opp_rel: np.ndarray, target: FollowTarget,
                       step: int) -> np.ndarray | None:
        """Mask of the rows of ``opp_rel`` that are the followed opponents of ``target``, matched to
        their predicted positions (within 3 m along and 1.5 m across the track); None when one of
        them is not found (overtaken, respawned, or out of the planners' window)."""
        rows = target.rows
        if len(opp_rel) == 0:
            return None
        elapsed = (step - target.step) * self.config.mpc.control_dt
        pred = (self.predict(target.ego_s, rows, np.array([elapsed]))[:, 0]
                - float(self.track.gap(ego_s, target.ego_s)))
        dist = ((opp_rel[None, :, 0] - pred[:, None]) / 3.0) ** 2 + ((opp_rel[None, :, 1] - rows[:, 1:2]) / 1.5) ** 2
        nearest = dist.argmin(axis=1)
        if (dist[np.arange(len(rows)), nearest] > 1.0).any():
            return None
        mask = np.zeros(len(opp_rel), dtype=bool)
        mask[nearest] = True
        return mask


@kernel
def _stay_behind(node_t, ego_v, decel, gap, opp_s, a0, alongside):
    """:meth:`PassOrFollow.can_stay_behind`: per opponent, the room ``opp_s - s_brake`` [m] to the ego braking
    at ``decel`` (:func:`~sofar_env.stack.prediction.braking_positions`, its formula) at every node; with
    ``alongside`` its minimum at least ``min(gap, a0) - 1e-6`` and its last value at least ``a0``, else its
    minimum at least ``a0``. One compiled call (:mod:`sofar_env._jit`): the minimum of the room is exact in any
    order, and a nan room never passes, as in the numpy form."""
    M, N = opp_s.shape
    v0 = 0.0 if ego_v < 0.0 else ego_v  # noqa: FURB136 (Python's max(ego_v, 0.0): nan and -0.0 kept)
    t_stop = v0 / decel
    s_brake = np.empty(N)
    for k in range(N):
        tt = minimum(node_t[k], t_stop)
        s_brake[k] = v0 * tt - 0.5 * decel * tt * tt
    out = np.empty(M, dtype=np.bool_)
    for i in range(M):
        low = np.inf
        for k in range(N):
            low = minimum(low, opp_s[i, k] - s_brake[k])
        if alongside:
            out[i] = low >= minimum(gap[i], a0) - 1e-6 and opp_s[i, N - 1] - s_brake[N - 1] >= a0
        else:
            out[i] = low >= a0
    return out
