"""Why the ego leaves the track: replay episodes that ended off the track, record their last seconds, classify.

An *off-track* is the end of an episode by a corner of the ego's footprint beyond a track edge
(:mod:`sofar_env.race`). :func:`record_off_track` runs one :class:`~sofar_agents.evaluation.protocol.EpisodeTask`
as :func:`~sofar_agents.evaluation.episode.run_episode` does and keeps one :class:`OffTrackRecord` per control
step for the last :data:`RECORD_SECONDS`: the ego's state and the track there, the plant's side-slip angle and
yaw rate (the dynamic world's single-track plant; 0 on the kinematic plant), the commanded acceleration, where
the MPC's plan ends laterally and how much room its footprint keeps to the edges along the plan, and the nearest
car.

Classification (:func:`classify`), the first rule that holds:

1. ``spin``: the side-slip angle reached :data:`SPIN_SLIP` in the last :data:`WINDOW` s: the car no longer
   goes where it points (the kinematic MPC's model no longer holds);
2. ``planned``: in at least half of the steps of the last second the MPC's own plan put a corner of the car
   beyond an edge (``plan_room`` < 0): the departure was the controller's plan;
3. ``left_plan``: the plan kept the car inside and the car left it (its tracking error at racing speed, or a
   push by the slope of the edge).

Evidence (:func:`classify`), at the last step unless named otherwise: speed, ``v^2 |kappa|`` (the lateral
acceleration the track's curvature asks for), whether the car left on the outside of the turn, the largest
side-slip over the window, the mean commanded acceleration over the last second, the *plan move* (the range of
the plan's final lateral offset over the window: how far the planners moved the car's target in that time), the
distance to the nearest car, whether the plan in force followed a car, and the largest slack of the MPC's
lateral-acceleration rows over the window (its plan beyond ``lat_acc_max``).
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import asdict, dataclass, field, fields

import numpy as np

from sofar_agents.evaluation.episode import make_env, run_episode
from sofar_agents.evaluation.protocol import EpisodeTask, ended_tasks
from sofar_agents.evaluation.results import EpisodeResult

__all__ = ["OffTrackRecord", "OffTrackReport", "CLASSES", "RECORD_SECONDS", "WINDOW", "SPIN_SLIP",
           "off_track_tasks", "record_off_track", "classify", "report_rows", "REPORT_COLUMNS"]

RECORD_SECONDS = 4.0
"""Seconds of records kept before the end of an episode."""
WINDOW = 2.0
"""Seconds before the departure over which the side-slip and the plan move are taken."""
SPIN_SLIP = 0.15
"""Side-slip angle [rad] from which the car counts as spinning (about 8.6 degrees; the dynamic world's cars drive
at below 0.05 rad in a corner taken at the speed profile)."""

CLASSES: dict[str, str] = {
    "spin": "the car spun (side-slip beyond SPIN_SLIP)",
    "planned": "the MPC's plan left the track",
    "left_plan": "the car left a plan that stayed on the track",
}
"""The classes of :func:`classify`, in the order of its rules."""


@dataclass
class OffTrackRecord:
    """One control step before a departure (module docstring)."""

    t: float
    s: float
    n: float
    e: float
    v: float
    kappa: float
    """Curvature of the track at the ego [1/m] (> 0: a left turn)."""
    width_left: float
    width_right: float
    beta: float
    """Side-slip angle of the plant, atan(vy / vx) [rad] (0 on the kinematic plant)."""
    yaw_rate: float
    """Yaw rate of the plant [rad/s] (the kinematic bicycle's on the kinematic plant)."""
    accel: float
    """Commanded acceleration, the MPC's first input [m/s^2]."""
    lat_slack: float
    """Largest slack of the MPC's lateral-acceleration rows [m/s^2]: how far its plan goes beyond
    ``lat_acc_max``."""
    mpc_status: str
    plan_n_end: float
    """Lateral offset at the end of the MPC's plan [m]."""
    plan_room: float
    """Smallest room of the planned footprint's corners to the edges along the plan [m] (< 0: the plan leaves)."""
    nearest: float
    """Distance to the nearest car in the Frenet frame [m] (inf: none)."""
    following: bool


@dataclass
class OffTrackReport:
    """One replayed episode: its result, and for an off-track its class, evidence and records."""

    task: EpisodeTask
    result: EpisodeResult
    label: str = ""
    cls: str = ""
    evidence: dict = field(default_factory=dict)
    records: list = field(default_factory=list)


def off_track_tasks(rows: Iterable[Mapping], stacks: Sequence[str] | None = None) -> list[EpisodeTask]:
    """The fixed-gamma episodes of per-episode CSV rows (typed, ``read_episode_csv``) that ended off the track."""
    return ended_tasks(rows, "off_track", stacks)


def _plan_room(track, ego_s: float, x_pred: np.ndarray, vehicle) -> float:
    """Smallest room [m] of the corners of the footprint planned in ``x_pred`` (s relative to ``ego_s``) to the
    edges (the footprint of :func:`sofar_env.geometry.footprint_corners` at each stage's n and heading error)."""
    s = ego_s + x_pred[:, 0]
    sin_e, cos_e = np.sin(x_pred[:, 2]), np.cos(x_pred[:, 2])
    ends = np.stack([vehicle.cg_to_front * sin_e, -vehicle.cg_to_rear * sin_e])
    half = 0.5 * vehicle.width * cos_e
    left = np.asarray(track.width_left(s), float) - (x_pred[:, 1] + ends.max(axis=0) + half)
    right = np.asarray(track.width_right(s), float) + (x_pred[:, 1] + ends.min(axis=0) - half)
    return float(min(left.min(), right.min()))


class _Recorder:
    """A fixed-gamma policy that records the previous step at each call (the env's last output is that step's)."""

    def __init__(self, env, gamma: float, steps: int):
        self.env, self.gamma = env.unwrapped, float(gamma)
        self.records: deque = deque(maxlen=steps)

    def __call__(self, obs):
        self.flush()
        return [self.gamma]

    def flush(self) -> None:
        env = self.env
        out = env.last_output
        if out is None:
            return
        race, track, stack = env.race, env.track, env.stack
        s, n, e, v, delta = (float(x) for x in race.frenet[0])
        veh = stack.vehicle
        if race.dynamic:
            vx, vy, yaw_rate = (float(x) for x in race.plant_states[0, 3:6])
            beta = math.atan2(vy, max(vx, 0.1))
        else:
            beta, yaw_rate = 0.0, v * math.tan(delta) / veh.wheelbase
        opp = race.opponent_frenet(0)
        nearest = math.inf
        if len(opp):
            gap = np.asarray(track.gap(opp[:, 0], s), float)
            nearest = float(np.hypot(gap, opp[:, 1] - n).min())
        mpc = out.mpc
        solved = mpc.status == "solved"
        self.records.append(OffTrackRecord(
            t=float(race.time), s=s, n=n, e=e, v=v, kappa=float(track.curvature(s)),
            width_left=float(track.width_left(s)), width_right=float(track.width_right(s)), beta=beta,
            yaw_rate=yaw_rate, accel=float(out.u[0]), lat_slack=float(mpc.slack.get("lat_acc", 0.0)),
            mpc_status=mpc.status,
            plan_n_end=float(mpc.x_pred[-1, 1]) if solved else math.nan,
            plan_room=_plan_room(track, float(out.ego_s), mpc.x_pred, veh) if solved else math.nan,
            nearest=nearest, following=bool(out.following)))


def record_off_track(task: EpisodeTask, label: str = "", env=None, seconds: float = RECORD_SECONDS) -> OffTrackReport:
    """Run ``task`` (a fixed gamma) and keep its last ``seconds`` of records; an off-track is classified.

    ``env``: an environment of ``task``'s track and settings to reuse (else one is built and closed). The
    controller runs as ``task.stack`` configures it (the recorder only reads its outputs)."""
    if task.strategy.kind != "fixed":
        raise ValueError(f"off-track replays take a fixed gamma, got strategy {task.strategy.name!r}")
    own = env is None
    if own:
        env = make_env(task.track, use_miqp=task.use_miqp, duration=task.duration, stack=task.stack,
                       scenario=task.scenario)
    try:
        dt = float(env.unwrapped.config.race.dt)
        recorder = _Recorder(env, task.strategy.gamma, max(int(round(seconds / dt)), 1))
        result, _ = run_episode(env, recorder, task)
        recorder.flush()  # the last step
    finally:
        if own:
            env.close()
    report = OffTrackReport(task, result, label)
    if result.off_track:
        report.records = list(recorder.records)
        report.cls, report.evidence = classify(report.records)
    return report


def classify(records: Sequence[OffTrackRecord], window: float = WINDOW) -> tuple[str, dict]:
    """The class of a departure from its records (module docstring) and the evidence."""
    records = list(records)
    if not records:
        return "left_plan", {"steps": 0}
    last = records[-1]
    w = [r for r in records if r.t > last.t - window + 1e-9]
    w1 = [r for r in records if r.t > last.t - 1.0 + 1e-9]
    slip = max(abs(r.beta) for r in w)
    rooms = [r.plan_room for r in w1 if not math.isnan(r.plan_room)]
    ends = [r.plan_n_end for r in w if not math.isnan(r.plan_n_end)]
    left_side = (last.width_left - last.n) < (last.width_right + last.n)
    ev = {
        "t": round(last.t, 1), "v": round(last.v, 1), "lat_demand": round(last.v ** 2 * abs(last.kappa), 1),
        "side": "left" if left_side else "right",
        "outside": bool(last.kappa != 0.0 and (left_side == (last.kappa < 0.0))),
        "slip": round(slip, 3), "accel": round(float(np.mean([r.accel for r in w1])), 2),
        "lat_slack": round(max(r.lat_slack for r in w), 2),
        "plan_move": round(max(ends) - min(ends), 2) if ends else math.nan,
        "plan_room": round(min(rooms), 2) if rooms else math.nan,
        "nearest": round(last.nearest, 1), "following": any(r.following for r in w), "e": round(last.e, 3),
    }
    if slip >= SPIN_SLIP:
        return "spin", ev
    if rooms and sum(x < 0.0 for x in rooms) * 2 >= len(rooms):
        return "planned", ev
    return "left_plan", ev


REPORT_COLUMNS = ("label", "track", "rho", "seed", "stack", "config_hash", "gamma", "outcome", "sim_time", "cls", "v",
                  "lat_demand", "side", "outside", "slip", "accel", "lat_slack", "plan_move", "plan_room", "nearest",
                  "following", "e", "wall_time")
"""Columns of :func:`report_rows` (one row per replayed episode)."""

RECORD_COLUMNS = ("label", "track", "rho", "seed", "stack", "gamma") + tuple(f.name for f in fields(OffTrackRecord))
"""Columns of the step records of :func:`record_rows`."""


def _outcome(result: EpisodeResult) -> str:
    for name in ("collision", "off_track", "stalled"):
        if getattr(result, name):
            return name
    return "success" if result.success else "ended"


def _ident(rep: OffTrackReport) -> dict:
    t = rep.task
    return {"label": rep.label, "track": t.track, "rho": f"{t.rho:g}", "seed": t.seed, "stack": t.stack,
            "gamma": f"{t.strategy.gamma:g}"}


def report_rows(reports: Iterable[OffTrackReport]) -> list[dict]:
    """One row per report (:data:`REPORT_COLUMNS`); the evidence columns are empty unless it left the track."""
    rows = []
    for rep in reports:
        row = {**_ident(rep), "config_hash": rep.result.config_hash, "outcome": _outcome(rep.result),
               "sim_time": f"{rep.result.sim_time:.1f}", "cls": rep.cls,
               "wall_time": f"{rep.result.wall_time:.1f}"}
        for k, v in rep.evidence.items():
            row[k] = int(v) if isinstance(v, bool) else v
        rows.append({c: row.get(c, "") for c in REPORT_COLUMNS})
    return rows


def record_rows(rep: OffTrackReport) -> list[dict]:
    """The step records of one report as rows (:data:`RECORD_COLUMNS`)."""
    ident = _ident(rep)
    return [{**ident, **{k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in asdict(r).items()}}
            for r in rep.records]
