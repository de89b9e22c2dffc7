"""Is a stall the optimum of the controller's problem? The MPC's problem at a stalled step, solved to convergence
with longer horizons and from other guesses.

A stalled episode (a fixed gamma) is replayed to the time ``at`` (inside the stall); the arguments of the last MPC
call (state, stage data, opponents, gamma) are kept, and the MPC's nonlinear program is solved with IPOPT
(:meth:`~sofar_env.control.mpc.MPCDCBF.reference_solution`):

* at the MPC's own horizon, on its own stage data, from its own warm start and from the guesses below;
* at each longer horizon of ``horizons`` (the same stage length ``ts``), on stage data looked up along the
  circuit (:class:`~sofar_env.stack.stage.StageLookup`) at arc lengths spread as by a 1 m/s creep, with the
  lateral reference held at the plan's last value, the speed reference capped at the stall's own largest, and
  the raw track edges (without the heading-error tightening of the own stage data);
* from three guesses: standing (the state held, no input), and creeping (1 m/s^2 up to 4 m/s) while moving
  0.5 m/s^2 towards the left or the right, inside the edges less 1.5 m.

Each solution is summarised by its speed at the first stage, when its plan starts to move (the first stage above
:data:`MOVING_SPEED`), its speed at the horizon's end, the range of its lateral offset, its largest barrier slack
and its objective; per horizon the solution of lowest objective counts, and the real-time iteration's own plan of
that step is listed with them (guess ``rti``). A plan *starts* when its first stage is faster than
:data:`STARTING_SPEED`. The verdict of a probed step:

* ``"drives"``: the controller's own plan starts (the standstill is ending, or the car creeps);
* ``"rti"``: it does not, but the converged plan at its own horizon starts (the standstill is the real-time
  iteration's, not the problem's);
* ``"waits"``: the converged plan at the own horizon moves, but only later in the horizon (at the next step the
  problem is the same and the wait starts again: receding-horizon procrastination);
* ``"horizon"``: the converged plan stands at the own horizon and moves at a longer one (the plan that drives off
  lies beyond the horizon);
* ``"stands"``: standing is the best plan found at every horizon tried.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from sofar_agents.evaluation.episode import make_env, reset_options
from sofar_agents.evaluation.protocol import EpisodeTask

__all__ = ["MOVING_SPEED", "STARTING_SPEED", "GUESSES", "ProbeRow", "StallProbe", "probe_problem", "probe_stall", "probe_markdown"]

MOVING_SPEED = 0.2
"""Planned speed above which a plan counts as moving [m/s]."""
STARTING_SPEED = 0.01
"""Speed of the first stage above which a plan starts at once [m/s]."""
GUESSES = ("own", "stand", "left", "right")
"""The guesses (module docstring); ``own``, the MPC's warm start, only at its own horizon."""


@dataclass(frozen=True)
class ProbeRow:
    """One converged solution."""

    horizon: int
    horizon_s: float
    """The horizon's length [s]."""
    guess: str
    success: bool
    v_first: float
    """Speed of the first stage [m/s]."""
    moves_from_s: float
    """Time of the first stage planned above :data:`MOVING_SPEED` [s]; nan when the plan stands."""
    v_end: float
    n_low: float
    n_high: float
    barrier_slack: float
    objective: float


@dataclass(frozen=True)
class StallProbe:
    """The probe of one stalled step."""

    task: EpisodeTask
    at: float
    """Simulated time of the probed step [s]."""
    state: tuple[float, ...]
    """(n, e, v, delta) of the ego there."""
    own_horizon: int
    rows: tuple[ProbeRow, ...]
    """The controller's own plan (guess ``rti``) and the converged solutions."""

    def best(self, horizon: int) -> ProbeRow | None:
        """The converged solution of lowest objective at ``horizon`` (None when none succeeded)."""
        ok = [r for r in self.rows if r.horizon == horizon and r.success and r.guess != "rti"]
        return min(ok, key=lambda r: r.objective) if ok else None

    @property
    def verdict(self) -> str:
        """``"drives"``, ``"rti"``, ``"waits"``, ``"horizon"`` or ``"stands"`` (module docstring); ``"failed"``
        without a converged solution at the own horizon."""
        rti = next(r for r in self.rows if r.guess == "rti")
        if rti.v_first > STARTING_SPEED:
            return "drives"
        own = self.best(self.own_horizon)
        if own is None:
            return "failed"
        if own.v_first > STARTING_SPEED:
            return "rti"
        if not math.isnan(own.moves_from_s):
            return "waits"
        longer = [self.best(h) for h in sorted({r.horizon for r in self.rows}) if h > self.own_horizon]
        return "horizon" if any(b is not None and not math.isnan(b.moves_from_s) for b in longer) else "stands"


def _guess(kind: str, x0: np.ndarray, t: np.ndarray, n_lo: np.ndarray, n_hi: np.ndarray):
    """States (N+1, 5) and inputs (N, 2) of a guess (module docstring)."""
    xg = np.repeat(x0[None, :], len(t), axis=0)
    ug = np.zeros((len(t) - 1, 2))
    if kind == "stand":
        return xg, ug
    side = 1.0 if kind == "left" else -1.0
    v = np.minimum(t, 4.0)
    xg[:, 0] = np.where(t < 4.0, 0.5 * t ** 2, 8.0 + 4.0 * (t - 4.0))
    xg[:, 3] = v
    lo, hi = n_lo + 1.5, n_hi - 1.5
    xg[:, 1] = np.where(lo <= hi, np.clip(x0[1] + side * 0.25 * t ** 2, lo, np.maximum(lo, hi)), x0[1])
    xg[:, 2] = 0.0
    ug[:, 0] = np.where(t[1:] <= 4.0, 1.0, 0.0)
    return xg, ug


def _row(mpc, horizon: int, guess: str, sol) -> ProbeRow:
    t = mpc.config.time_grid()
    if not sol.success:
        nan = math.nan
        return ProbeRow(horizon, float(t[-1]), guess, False, nan, nan, nan, nan, nan, nan, nan)
    moving = np.flatnonzero(sol.x[:, 3] > MOVING_SPEED)
    slack = float(sol.slack_barrier.max()) if sol.slack_barrier.size else 0.0
    return ProbeRow(horizon, float(t[-1]), guess, True, float(sol.x[1, 3]),
                    float(t[moving[0]]) if len(moving) else math.nan,
                    float(sol.x[-1, 3]), float(sol.x[:, 1].min()), float(sol.x[:, 1].max()), max(slack, 0.0),
                    float(sol.objective))


def _rti_row(mpc, result) -> ProbeRow:
    """The controller's own plan of the step (its :class:`~sofar_env.control.mpc.MPCResult`)."""
    t = mpc.config.time_grid()
    moving = np.flatnonzero(result.x_pred[:, 3] > MOVING_SPEED)
    return ProbeRow(mpc.config.horizon, float(t[-1]), "rti", bool(result.success), float(result.x_pred[1, 3]),
                    float(t[moving[0]]) if len(moving) else math.nan, float(result.x_pred[-1, 3]),
                    float(result.x_pred[:, 1].min()), float(result.x_pred[:, 1].max()),
                    float(result.slack.get("barrier", 0.0)), math.nan)


def probe_problem(mpc, stage, x0: np.ndarray, opponents: np.ndarray, gamma: float, lookup, ego_s: float,
                  horizons: Sequence[int]) -> list[ProbeRow]:
    """The solutions of one MPC call (module docstring): ``mpc`` the MPC in force (left as it was), ``stage`` its
    stage data, ``lookup`` the circuit's :class:`~sofar_env.stack.stage.StageLookup`, ``ego_s`` the ego's arc
    length [m]."""
    from sofar_env.control.mpc import MPCDCBF
    from sofar_env.control.mpc.types import MPCStageData

    own_n = mpc.config.horizon
    rows = []
    t = mpc.config.time_grid()
    rows.append(_row(mpc, own_n, "own", mpc.reference_solution(x0, stage, opponents, gamma)))
    for kind in GUESSES[1:]:
        rows.append(_row(mpc, own_n, kind, mpc.reference_solution(
            x0, stage, opponents, gamma, guess=_guess(kind, x0, t, stage.n_min, stage.n_max))))
    for h in horizons:
        if h == own_n:
            continue
        longer = MPCDCBF(replace(mpc.config, horizon=int(h)), mpc.vehicle)
        th = longer.config.time_grid()
        _, kappa, v_ref, n_min, n_max = lookup(ego_s, np.asarray(th, float))  # a 1 m/s creep: s_rel = t
        data = MPCStageData(kappa=kappa, n_ref=np.full(len(th), float(stage.n_ref[-1])),
                            v_ref=np.minimum(v_ref, float(np.max(stage.v_ref))), n_min=n_min, n_max=n_max)
        for kind in GUESSES[1:]:
            rows.append(_row(longer, int(h), kind, longer.reference_solution(
                x0, data, opponents, gamma, guess=_guess(kind, x0, th, n_min, n_max))))
    return rows


def probe_stall(task: EpisodeTask, times: Sequence[float], horizons: Sequence[int] = (20, 40, 80)) -> list[StallProbe]:
    """Replay ``task`` (a fixed gamma) once and probe its last MPC call before each simulated time of ``times``
    [s] (:func:`probe_problem`). Raises ``ValueError`` for another strategy, a time outside the episode, a horizon
    below 2 stages, or an episode that ends before the last time."""
    from sofar_env.stack.stage import StageLookup

    if task.strategy.kind != "fixed":
        raise ValueError(f"a probe takes a fixed gamma, got strategy {task.strategy.name!r}")
    times = sorted(float(t) for t in times)
    if not times or not all(math.isfinite(t) and 0.0 < t <= task.duration for t in times):
        raise ValueError(f"times must lie in (0, {task.duration:g}] s, got {times!r}")
    if any(int(h) < 2 for h in horizons):
        raise ValueError(f"horizons must be >= 2 stages, got {list(horizons)}")
    env = make_env(task.track, use_miqp=task.use_miqp, duration=task.duration, stack=task.stack,
                   scenario=task.scenario)
    try:
        u = env.unwrapped
        env.reset(seed=int(task.seed), options=reset_options(task))
        last: list = []
        near = [False]  # the next step may be the probed one: keep the MPC as it was before its solve
        for mpc in u.stack.mpcs:
            solve = type(mpc).solve.__get__(mpc)

            def recorded(x0, stage, opponents, gamma, _solve=solve, _mpc=mpc):
                before = copy.deepcopy(_mpc) if near[0] else None
                result = _solve(x0, stage, opponents, gamma)
                last[:] = [(before, np.array(x0, float), stage, np.array(opponents, float), float(gamma), result)]
                return result

            mpc.solve = recorded
        action = np.array([task.strategy.gamma], np.float32)
        lookup = StageLookup(u.track, u.stack.edges, u.stack.config.speed_factor)
        probes = []
        dt = float(u.race.config.dt)
        for at in times:
            while u.race.time < at - 1e-9:
                near[0] = u.race.time >= at - 1.5 * dt
                _, _, terminated, truncated, _ = env.step(action)
                if terminated or truncated:
                    raise ValueError(f"the episode ended at {u.race.time:.1f} s, before {at:g} s")
            before, x0, stage, opp, gamma, result = last[0]
            rows = [_rti_row(before, result),
                    *probe_problem(before, stage, x0, opp, gamma, lookup, float(u.last_output.ego_s), horizons)]
            probes.append(StallProbe(task, float(u.race.time), tuple(float(v) for v in x0[1:5]),
                                     before.config.horizon, tuple(rows)))
        return probes
    finally:
        env.close()


def probe_markdown(probes: Sequence[StallProbe], command: str = "") -> str:
    """A Markdown report: per stall its verdict, and every solution."""
    lines = ["# Stalls probed: the MPC's problem at a stalled step, solved to convergence (IPOPT)", "",
             "Verdict of a probed step: `drives` (the controller's own plan starts: its first stage faster than "
             f"{STARTING_SPEED:g} m/s), `rti` (it does not, the converged plan at its own horizon starts), `waits` "
             "(the converged plan at the own horizon moves only later in the horizon), `horizon` (it stands there "
             "and moves at a longer horizon), `stands` (standing is the best plan found at every horizon tried); "
             "per horizon the converged solution of lowest objective counts. Rows: `rti` the controller's own plan; "
             "guesses `own` (the MPC's warm start), `stand`, `left`, `right` (creeping towards that side).", "",
             "| stack | world | circuit | rho | seed | gamma | at [s] | n, e, v | verdict |",
             "|---|---|---|---:|---:|---:|---:|---|---|"]
    for p in probes:
        t = p.task
        world = t.scenario + (f", {t.n_opponents} opponents" if t.n_opponents is not None else "")
        lines.append(f"| {t.stack} | {world} | {t.track} | {t.rho:g} | {t.seed} | {t.strategy.gamma:g} | {p.at:.1f} | "
                     f"{p.state[0]:.2f} m, {p.state[1]:.3f} rad, {p.state[2]:.2f} m/s | **{p.verdict}** |")
    lines += ["", "| circuit, seed, gamma, time | horizon | guess | v first stage [m/s] | moves from [s] "
              "| v at the end [m/s] | lateral range [m] | largest barrier slack | objective |",
              "|---|---|---|---:|---:|---:|---|---:|---:|"]
    for p in probes:
        for r in p.rows:
            if not r.success:
                lines.append(f"| {p.task.track}, {p.task.seed}, {p.task.strategy.gamma:g}, {p.at:.1f} s | {r.horizon} "
                             f"({r.horizon_s:.1f} s) | {r.guess} | failed | | | | | |")
                continue
            best = " (best)" if p.best(r.horizon) is r else ""
            moves = "stands" if math.isnan(r.moves_from_s) else f"{r.moves_from_s:.2f}"
            objective = "" if math.isnan(r.objective) else f"{r.objective:,.0f}"
            lines.append(f"| {p.task.track}, {p.task.seed}, {p.task.strategy.gamma:g}, {p.at:.1f} s | {r.horizon} "
                         f"({r.horizon_s:.1f} s) | {r.guess}{best} | {r.v_first:.3f} | {moves} | {r.v_end:.2f} | "
                         f"{r.n_low:.2f} to {r.n_high:.2f} | {r.barrier_slack:.3f} | {objective} |")
    if command:
        lines += ["", f"Command: `{command}`"]
    return "\n".join(lines) + "\n"
