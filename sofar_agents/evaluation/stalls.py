"""Why the ego stalls: replay or run episodes, record the slow phase step by step, classify each stall.

A *stall* is the end of an episode by the stall rule (:mod:`sofar_env.core`): the ego slower than
``stall_speed`` (1 m/s) for ``stall_seconds`` (20 s) without interruption. :func:`record_episode` runs one
:class:`~sofar_agents.evaluation.protocol.EpisodeTask` (a replay of a committed row, or a new episode) as
:func:`~sofar_agents.evaluation.episode.run_episode` does, and records one :class:`StepRecord` per control step
while the ego is slower than :data:`RECORD_SPEED` (the records of a faster step are dropped, so the records
left at the end are the final slow phase). Each record holds what the controller saw and did in that step:

* the MIQP's decision (``follow``, ``left`` / ``right``: the side planned for the nearest car ahead that the
  plan clears, ``free``: no car to clear), the plan's status, its largest clearance violation and the speed
  of the followed car;
* the MPC's status (``solved`` or a fallback), its track and barrier slacks, ``h`` at the current state,
  the planned speed (largest over the horizon) and the speed reference it was given (largest over the
  horizon, after the follow cap);
* the nearest car ahead that the controller sees (gap, lateral offset, speed) and the free width beside it
  (the wider of its two sides, edge to its body);
* the ego's heading error ``e`` to the track, the room of its footprint's corners to the edges, the
  *turn-back room* (the planners' edges less the MPC's ``track_margin``, on the side the car is turned towards,
  minus the largest offset of its front end while it turns back at full lock: the recoverable envelope of
  :class:`~sofar_env.control.mpc.ends.EndOffsets`) and the *row room* (the same edge minus what the MPC's own
  track rows bound, :func:`rooms`; < 0: those rows are violated at this state).

* whether the car ahead is held by a *squeezed* car (``squeezed_ahead``, in truth): the nearest opponent ahead
  within :data:`NEAR_GAP` is slower than 1 m/s and squeezed (its traffic rule makes it brake,
  :mod:`sofar_env.opponents.steering`), or stands in a queue of cars slower than 1 m/s, each within
  :data:`QUEUE_GAP` of the next, that a squeezed car leads (nan in records of an earlier version of the recorder).

Classification (:func:`classify`), on the *window*: the last :data:`WINDOW_STEPS` records (the final 10 s of
the stall). A property holds when it holds in at least half of the window's steps. The first rule that
holds gives the class:

0. ``squeeze_deadlock`` (the world holds the car ahead): the car ahead is held by a squeezed car
   (``squeezed_ahead``). With ``TrafficConfig.yield_to_any`` (the worlds ``"interactive"`` and ``"dynamic"``) a
   car squeezed by a standing ego behind it brakes to a standstill and stays squeezed while both stand: whatever
   the controller then plans, that car will not move. (The controller may still pass it where there is room.)
1. ``mpc_fallback`` (no feasible forward plan): the MPC's status is a fallback (its QP failed).
2. ``follow_hold`` (a follow decision that never releases): the plan in force follows a car and the speed
   reference the MPC gets, capped by that follow decision, stays below 1 m/s over the whole horizon.
3. ``stopped_ahead_no_room`` (a car stopped ahead with no room): a car is ahead within
   :data:`NEAR_GAP` (gap between reference points), slower than 1 m/s, and the free width on both of its
   sides is less than the ego's width plus 2 x 0.25 m.
4. ``edge_no_turn_back`` (angled at an edge with no room to turn back): ``|e| >=`` :data:`ANGLE` and the row
   room is below :data:`ROOM`: the MPC's own track rows leave (almost) nothing, so that every forward move its
   model can make costs track slack.
5. ``zero_plan`` (the MPC solves a standstill): it solved, its speed reference is at least 1 m/s, yet its plan
   is below 1 m/s at the next step (it may plan to start later in the horizon, and re-plans the same wait at
   every step). The evidence ``away`` is the share of steps in which the car is turned away from the MPC's
   lateral reference (``e (n_ref - n) < 0``): driving off then first takes it further from that reference.
6. ``other``: none of the above.

Evidence (:func:`classify`): medians over the window of the record fields, the most frequent decision, the
shares ``squeezed``, ``fallback``, ``follow``, ``stopped_ahead``, ``angled`` and ``away``, and the *onset* (the
first record of the last uninterrupted run below 1 m/s, where the stall began: time, decision, heading error, gap to
and speed of the car ahead).

"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

import numpy as np

from sofar_agents.evaluation.episode import make_env, run_episode
from sofar_agents.evaluation.protocol import EpisodeTask
from sofar_agents.evaluation.results import EpisodeResult

__all__ = ["StepRecord", "StallReport", "CLASSES", "RECORD_SPEED", "WINDOW_STEPS", "NEAR_GAP", "QUEUE_GAP", "ANGLE",
           "ROOM", "record_episode", "classify", "rooms"]

RECORD_SPEED = 3.0
"""Steps slower than this [m/s] are recorded; a faster step drops the records (the final slow phase is left)."""
WINDOW_STEPS = 100
"""Records the classification looks at: the last 10 s of the stall."""
NEAR_GAP = 15.0
"""A car ahead counts as blocking within this gap between reference points [m] (two car lengths and more)."""
QUEUE_GAP = 20.0
"""Two standing cars one behind the other within this gap [m] are one queue (the traffic's ``follow_gap`` is 12 m)."""
ANGLE = 0.31
"""Heading error [rad] from which a car turned towards an edge cannot drive away from it without its front end
first moving further out (``e*`` of :class:`~sofar_env.control.mpc.ends.EndOffsets`, AV-21)."""
ROOM = 0.1
"""Room of the MPC's own track rows [m] (``row_room``) below which the car counts as having no room to turn back."""
SLOW = 1.0  # the stall rule's speed [m/s]
_BUFFER = 0.25
"""Lateral buffer beside a stopped car, each side [m] (that of the MPC's track margin)."""
_HALF_WIDTH = 0.95
"""Half the AV-21's width [m] (``VehicleParams.width`` / 2; the MPC's track margin is it plus 0.25 m)."""

CLASSES: dict[str, str] = {
    "squeeze_deadlock": "car ahead held at a standstill by the world's squeeze rule",
    "mpc_fallback": "no feasible forward plan (MPC fallback loop)",
    "follow_hold": "follow decision that never releases",
    "stopped_ahead_no_room": "car stopped ahead with no room",
    "edge_no_turn_back": "angled at an edge with no room to turn back",
    "zero_plan": "MPC solves, plans standstill",
    "other": "other",
}
"""The classes of :func:`classify`, in the order of its rules, with their descriptions."""


@dataclass
class StepRecord:
    """What the controller saw and did in one control step (module docstring)."""

    step: int
    t: float
    s: float
    n: float
    e: float
    v: float
    delta: float
    decision: str
    """``follow``, ``left``, ``right`` or ``free``."""
    plan_status: str
    plan_slack: float
    """Largest clearance violation of the MIQP plan in force [m]."""
    followed_v: float
    """Speed of the slowest followed car when the follow plan was made [m/s] (nan: none followed)."""
    mpc_status: str
    track_slack: float
    barrier_slack: float
    h_min: float
    v_plan: float
    """Largest planned speed over the MPC horizon [m/s]."""
    v_next: float
    """Planned speed at the end of the first interval (the next control step) [m/s]."""
    v_ref: float
    """Largest speed reference over the horizon (after the follow cap) [m/s]."""
    n_ref: float
    """Lateral reference at the end of the horizon [m]."""
    accel: float
    gap_ahead: float
    """Gap to the nearest car ahead the controller sees [m] (inf: none)."""
    n_ahead: float
    v_ahead: float
    room_beside: float
    """Free width on the wider side of that car, edge to body [m] (nan: none)."""
    corner_room: float
    """Smallest distance of a footprint corner to its edge [m] (< 0: outside)."""
    turn_room: float
    """Turn-back room on the side the car is turned towards [m] (module docstring)."""
    row_room: float = math.nan
    """Room the MPC's own track rows leave at this state on the side the car is turned towards [m] (:func:`rooms`;
    < 0: the rows are violated, any forward move that does not bring them back costs slack)."""
    squeezed_ahead: float = math.nan
    """1 when the car ahead is, in truth, held by a squeezed car (module docstring), else 0 (nan: not recorded)."""


@dataclass
class StallReport:
    """One episode's outcome, and for a stall its class and the evidence of the window."""

    task: EpisodeTask
    result: EpisodeResult
    label: str = ""  # where the episode comes from (a committed CSV, or a fresh seed set)
    cls: str = ""  # class of :func:`classify` ("" when the episode did not stall)
    evidence: dict = field(default_factory=dict)
    records: list = field(default_factory=list)
    restarts: int = 0
    """Times the controller's restart mode came on in the episode (``StackConfig.restart_lateral_weight``; the
    counter ``slow_restarts``)."""


class _Recorder:
    """Hooks one environment's controller: keeps the stage data of every MPC solve (its speed reference)."""

    def __init__(self, env):
        self.env = env.unwrapped
        self.stage = None
        self.x0 = None
        self._plan_id, self._side = None, "free"

    def install(self) -> None:
        """Record the stage data of every solve of each of the stack's MPCs (the restart mode's and the slow end
        rows' too)."""
        for mpc in self.env.stack.mpcs:
            mpc.solve = self._recording(type(mpc).solve.__get__(mpc))

    def _recording(self, solve):
        def recorded(x0, stage, opponents, gamma):
            self.stage, self.x0 = stage, np.asarray(x0, float)
            return solve(x0, stage, opponents, gamma)

        return recorded

    def record(self, step: int) -> StepRecord:
        env = self.env
        stack, race, track = env.stack, env.race, env.track
        out = env.last_output
        veh = stack.vehicle
        x0 = self.x0
        s = float(out.ego_s)
        n, e, v, delta = (float(x) for x in x0[1:5])
        plan = out.plan
        opp = np.asarray(out.opponents_rel, float).reshape(-1, 3)
        ahead = np.flatnonzero(opp[:, 0] > 0.0)
        k = ahead[np.argmin(opp[ahead, 0])] if len(ahead) else None
        decision = "free"
        if out.following:
            decision = "follow"
        elif plan is not None and len(opp):
            if out.miqp_ran or self._plan_id != id(plan):  # the sides index the rows the plan was made with
                self._plan_id, self._side = id(plan), "free"
                sides = np.asarray(plan.sides)
                cleared = [i for i in ahead if i < len(sides) and sides[i] != 0]
                if cleared:
                    i = min(cleared, key=lambda j: opp[j, 0])
                    self._side = "left" if sides[i] > 0 else "right"
            decision = self._side
        target = stack.pass_or_follow.target
        followed_v = float(target.rows[:, 2].min()) if target is not None and len(target.rows) else math.nan
        mpc = out.mpc
        half = 0.5 * veh.width
        room_beside = math.nan
        gap = n_o = v_o = math.inf
        if k is not None:
            gap, n_o, v_o = (float(x) for x in opp[k])
            s_o = s + gap
            wl, wr = float(track.width_left(s_o)), float(track.width_right(s_o))
            room_beside = max(wl - (n_o + half), (n_o - half) + wr)
        return StepRecord(
            step=step, t=float(race.time), s=s, n=n, e=e, v=v, delta=delta, decision=decision,
            squeezed_ahead=_squeezed_ahead(race.opponents),
            plan_status=plan.status if plan is not None else "", plan_slack=float(plan.max_slack) if plan else 0.0,
            followed_v=followed_v, mpc_status=mpc.status, track_slack=float(mpc.slack.get("track", 0.0)),
            barrier_slack=float(mpc.slack.get("barrier", 0.0)), h_min=float(mpc.barrier_min),
            v_plan=float(np.max(mpc.x_pred[:, 3])), v_next=float(mpc.x_pred[1, 3]),
            v_ref=float(np.max(self.stage.v_ref)),
            n_ref=float(self.stage.n_ref[-1]), accel=float(mpc.u[0]),
            gap_ahead=gap, n_ahead=n_o, v_ahead=v_o, room_beside=room_beside,
            corner_room=_corner_room(track, veh, s, n, e),
            **rooms(stack.edges, veh, stack.mpc_in_force.config, s, n, e))


def _squeezed_ahead(field) -> float:
    """:attr:`StepRecord.squeezed_ahead` of the opponent field ``field`` (:class:`~sofar_env.opponents.Opponents`):
    1 when the nearest car ahead within :data:`NEAR_GAP` heads a standing queue, or stands in one, that a squeezed
    car leads (each car slower than 1 m/s and within :data:`QUEUE_GAP` of the one behind it), else 0."""
    order = np.argsort(field.rel)
    squeezed, rel, v = field.squeezed, field.rel, field.v
    last, reach = 0.0, NEAR_GAP  # from the ego to the car ahead, then along the queue
    for k in order[rel[order] > 0.0]:
        if rel[k] - last > reach or abs(float(v[k])) >= SLOW:
            return 0.0
        if squeezed[k]:
            return 1.0
        last, reach = float(rel[k]), QUEUE_GAP
    return 0.0


def rooms(edges, vehicle, mpc_config, s: float, n: float, e: float) -> dict[str, float]:
    """``turn_room`` and ``row_room`` [m] of the ego at ``(s, n, e)``, on the side it is turned towards.

    Both against the planners' edges at ``s`` (``edges``: :class:`~sofar_env.stack.edges.TrackEdges`, the narrowest
    within the car's length) less the MPC's ``track_margin``. ``turn_room``: less the largest offset of the front
    end while the car turns back at full lock (the recoverable envelope). ``row_room``: less what the MPC's own
    rows bound (``mpc_config.track_rows``): the reference point within edges tightened by ``l |sin e|``
    (``"reference"``, the swing frozen at the current heading), the front end ``n + l sin e`` (``"ends"``), or the
    envelope (``"recoverable"``: equal to ``turn_room``)."""
    from sofar_env.control.mpc.ends import EndOffsets

    lo, hi = (float(x[0]) for x in edges(np.array([s])))
    margin = mpc_config.track_margin
    lo, hi = lo + margin, hi - margin
    g = EndOffsets(vehicle, recoverable=True)(np.array([e]))[0][:, 0]  # front up, front low, rear up, rear low
    reach = max(vehicle.cg_to_front, vehicle.cg_to_rear)
    left = e >= 0.0
    turn = hi - (n + g[0]) if left else (n + g[1]) - lo
    if mpc_config.track_rows.startswith("recoverable"):  # the curved rows: the room on a straight
        row = turn
    elif mpc_config.track_rows == "ends":
        row = hi - (n + reach * math.sin(e)) if left else (n + reach * math.sin(e)) - lo
    else:
        swing = reach * math.sin(min(abs(e), 0.5 * math.pi))
        row = hi - swing - n if left else n - (lo + swing)
    return {"turn_room": float(turn), "row_room": float(row)}


def _corner_room(track, veh, s: float, n: float, e: float) -> float:
    """Smallest distance [m] of the footprint's four corners to the edge on their side (< 0: outside)."""
    half = 0.5 * veh.width
    c, sn = math.cos(e), math.sin(e)
    room = math.inf
    for lon in (veh.cg_to_front, -veh.cg_to_rear):
        for lat in (half, -half):
            cs = s + lon * c - lat * sn
            cn = n + lon * sn + lat * c
            room = min(room, float(track.width_left(cs)) - cn, cn + float(track.width_right(cs)))
    return room


class _Policy:
    """Fixed gamma; records the previous step at each call (the env's last output is that step's)."""

    def __init__(self, gamma: float, recorder: _Recorder, keep: list):
        self.gamma, self.recorder, self.keep = float(gamma), recorder, keep
        self.k = 0

    def __call__(self, obs):
        if self.k == 0:
            self.recorder.install()
        else:
            self.flush()
        self.k += 1
        return [self.gamma]

    def flush(self) -> None:
        env = self.recorder.env
        if env.last_output is None or self.recorder.stage is None:
            return
        if float(self.recorder.x0[3]) < RECORD_SPEED:
            self.keep.append(self.recorder.record(self.k))
        else:
            self.keep.clear()


def record_episode(task: EpisodeTask, label: str = "", env=None) -> StallReport:
    """Run ``task`` (a fixed gamma) and record its final slow phase; a stall is classified (:func:`classify`).

    ``env``: an environment of ``task``'s track and settings to reuse (else one is built and closed). The
    controller runs as ``task.stack`` configures it (the recorder only reads its solves)."""
    if task.strategy.kind != "fixed":
        raise ValueError(f"stall replays take a fixed gamma, got strategy {task.strategy.name!r}")
    own = env is None
    if own:
        env = make_env(task.track, use_miqp=task.use_miqp, duration=task.duration, stack=task.stack,
                       scenario=task.scenario)
    try:
        records: list[StepRecord] = []
        recorder = _Recorder(env)
        policy = _Policy(task.strategy.gamma, recorder, records)
        result, _ = run_episode(env, policy, task)
        policy.flush()  # the last step
        restarts = int(env.unwrapped.stack.counters.get("slow_restarts", 0))
    finally:
        if own:
            env.close()
    report = StallReport(task, result, label, restarts=restarts)
    if result.stalled:
        report.cls, report.evidence = classify(records)
        report.records = _stall_phase(records)
    return report


def _stall_phase(records: list, lead: int = 20) -> list:
    """The records kept of a stall: its last run below 1 m/s (the stall) and ``lead`` steps before it."""
    k = len(records)
    while k > 0 and records[k - 1].v < SLOW:
        k -= 1
    return records[max(k - lead, 0):]


def _share(flags: Iterable[bool]) -> float:
    flags = [bool(f) for f in flags]
    return sum(flags) / max(len(flags), 1)


def classify(records: Sequence[StepRecord], window: int = WINDOW_STEPS) -> tuple[str, dict]:
    """The class of a stall from its records (module docstring) and the evidence: medians and shares over the
    window."""
    records = list(records)
    w = records[-window:]
    if not w:
        return "other", {"steps": 0}
    med = {name: float(np.nanmedian([getattr(r, name) for r in w]))
           for name in ("e", "v_plan", "v_next", "v_ref", "n_ref", "accel", "gap_ahead", "v_ahead", "room_beside",
                        "corner_room", "turn_room", "row_room",
                        "track_slack", "barrier_slack", "h_min", "plan_slack", "followed_v", "n")
           if not all(math.isnan(getattr(r, name)) for r in w)}
    decisions = Counter(r.decision for r in w)
    ev = {"steps": len(w), "t_end": w[-1].t, **{k: round(v, 3) for k, v in med.items()},
          "decision": decisions.most_common(1)[0][0],
          "fallback": round(_share(r.mpc_status != "solved" for r in w), 2),
          "follow": round(_share(r.decision == "follow" for r in w), 2)}
    k = len(records) - len(_stall_phase(records, 0))
    onset = records[min(k, len(records) - 1)]  # how the car came to stand: the first step of the last run below 1 m/s
    ev.update(onset_t=round(onset.t, 1), onset_decision=onset.decision, onset_e=round(onset.e, 3),
              onset_gap=round(onset.gap_ahead, 1), onset_v_ahead=round(onset.v_ahead, 2))
    width = 2.0 * abs(_HALF_WIDTH) + 2.0 * _BUFFER
    stopped = [r.gap_ahead <= NEAR_GAP and r.v_ahead < SLOW for r in w]
    ev["stopped_ahead"] = round(_share(stopped), 2)
    ev["angled"] = round(_share(abs(r.e) >= ANGLE for r in w), 2)
    ev["away"] = round(_share(r.e * (r.n_ref - r.n) < 0.0 for r in w), 2)
    ev["squeezed"] = round(_share(r.squeezed_ahead == 1.0 for r in w), 2)
    if ev["squeezed"] >= 0.5:
        return "squeeze_deadlock", ev
    if ev["fallback"] >= 0.5:
        return "mpc_fallback", ev
    if _share(r.decision == "follow" and r.v_ref < SLOW for r in w) >= 0.5:
        return "follow_hold", ev
    if _share(s and r.room_beside < width for s, r in zip(stopped, w)) >= 0.5:
        return "stopped_ahead_no_room", ev
    if _share(abs(r.e) >= ANGLE and r.row_room < ROOM for r in w) >= 0.5:
        return "edge_no_turn_back", ev
    if _share(r.mpc_status == "solved" and r.v_ref >= SLOW and r.v_next < SLOW for r in w) >= 0.5:
        return "zero_plan", ev
    return "other", ev
