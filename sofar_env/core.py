"""The controlled race: one simulation core under the Gymnasium and the PettingZoo adapters.

:class:`ControlledRace` owns everything a step of either environment does:

* the world (:class:`~sofar_env.race.Race`: plant, scripted opponents, events),
* one :class:`~sofar_env.stack.OvertakingStack` per controlled car,
* the per-decision tally of each car (:class:`DecisionTally`: the reward vector summed over
  the control steps of one decision, the events, the solver counters),
* the observation, reward vector and info of each car.

The adapters (:mod:`sofar_env.env`, :mod:`sofar_env.multi_agent`) only translate between
this core and their API: spaces, seeding, action parsing, the Gymnasium / PettingZoo
return conventions and rendering. Neither steps a stack or a race itself.

One decision of the live cars (:meth:`ControlledRace.step`), repeated ``decision_interval``
times with gamma held:

1. each running car's stack computes its control from its own Frenet state and the rows
   ``(s, n, v)`` of everything it must avoid (:meth:`Race.opponent_frenet`);
2. the race integrates all controls over ``dt`` and reports each car's events (collision,
   leaving the track, overtakes, progress);
3. each car's tally adds the step's reward vector; a car that collided, left the track or
   stalled stops running (in a multi-car race it also leaves the race: :meth:`Race.deactivate`).

The stall rule (``EnvConfig.stall_speed``, ``stall_seconds``): a car whose speed stays below
``stall_speed`` for ``stall_seconds`` without interruption has *stalled*; its episode
terminates with ``info["stalled"] = True`` and ``is_success = False`` (it stands still, e.g.
behind a car it cannot pass; nothing more happens in that episode). No reward term is added.

An episode runs from a successful :meth:`ControlledRace.reset` until every car has terminated or been
truncated (:attr:`ControlledRace.running`). :meth:`ControlledRace.step` outside an episode (before the
first successful reset, after a reset that failed part-way, or after the episode ended) raises
:class:`~sofar_env.errors.ResetNeeded` and changes nothing; a reset whose options are invalid raises before
anything changes, so the episode it interrupted goes on.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from .config import EnvConfig, apply_overrides
from .constants import GAMMA_MAX, GAMMA_MIN
from .control.barrier import min_barrier
from .errors import ResetNeeded
from .observation import observe
from .rewards import reward_vector, safety_cost, scalarize

__all__ = ["ControlledRace", "CarStep", "DecisionTally", "min_barrier", "parse_gamma"]


def parse_gamma(action: Any) -> float:
    """The scalar gamma of an action, validated once at the API boundary.

    Raises ``ValueError`` unless ``action`` is exactly one finite real number; a finite
    value outside ``[GAMMA_MIN, GAMMA_MAX]`` is clipped into it. Below this point gamma is
    only asserted.
    """
    arr = np.asarray(action)
    if arr.dtype.kind not in "iuf":  # strings, None, booleans, objects: not a number, whatever they spell
        raise ValueError(f"the action must be one real number (gamma) in [{GAMMA_MIN}, {GAMMA_MAX}], got "
                         f"{action!r} of type {type(action).__name__}")
    a = arr.astype(float).reshape(-1)
    if a.size != 1:
        raise ValueError(f"the action must hold exactly one value (gamma), got shape {np.shape(action)}")
    g = float(a[0])
    if not math.isfinite(g):
        raise ValueError(f"non-finite action {g!r}: gamma must be a finite number in [{GAMMA_MIN}, {GAMMA_MAX}]")
    return min(max(g, GAMMA_MIN), GAMMA_MAX)


class DecisionTally:
    """Sums the per-control-step terms of one car over one decision (``decision_interval`` steps)."""

    def __init__(self, n_objectives: int = 5) -> None:
        self.vector = np.zeros(n_objectives)
        self.cost = 0.0
        self.barrier_slack = 0.0
        self.mpc_time = 0.0
        self.miqp_time = 0.0
        self.collision = False
        self.off_track = False
        self.stalled = False
        self.min_h = math.inf
        self.min_h_of: tuple | None = None
        """The opponent rows and barrier of the last :attr:`min_h` (whose value the observation reuses when it
        measures the same rows, from the same state, with the same barrier)."""
        self.nearest = math.inf
        self.gamma = math.nan
        self.last = None

    def add(self, race, car: int, out, events, opponents_after: np.ndarray, profile_speed: float,
            previous_gamma: float, barrier_params) -> None:
        """Record one control step of car ``car``: ``out`` its stack output, ``events`` its CarEvents,
        ``opponents_after`` its opponent rows after the step, ``profile_speed`` the speed profile at its
        arc length before the step [m/s]."""
        slack = float(out.mpc.slack.get("barrier", 0.0))
        self.min_h = min_barrier(race.track, race.frenet[car], opponents_after, barrier_params)
        self.min_h_of = (opponents_after, barrier_params)
        self.nearest = race.nearest_distance(car)  # now: a crashed car may be removed from the race next
        self.vector += reward_vector(
            collision=events.collision, off_track=events.off_track, overtakes=events.overtakes,
            progress=events.progress, profile_speed=profile_speed, dt=race.config.dt, barrier_slack=slack,
            min_h=self.min_h, gamma=out.gamma, previous_gamma=previous_gamma,
        )
        self.cost += safety_cost(events.collision, events.off_track, slack)
        self.barrier_slack = max(self.barrier_slack, slack)
        self.mpc_time += out.mpc_time
        self.miqp_time += out.miqp_time
        self.collision |= events.collision
        self.off_track |= events.off_track
        self.gamma = out.gamma
        self.last = out

    @property
    def terminated(self) -> bool:
        return self.collision or self.off_track or self.stalled

    def info(self, race, stack, car: int = 0, timings: bool = False) -> dict:
        """The per-step info dictionary (see the environment docstring); ``timings`` adds the solve times."""
        out = self.last
        plan = out.plan if out is not None else None
        info = {
            "reward_vector": self.vector.astype(np.float32),
            "cost": self.cost,
            "overtakes": int(race.overtakes[car]),
            "laps": race.laps(car),
            "sim_time": race.time,
            "gamma": self.gamma,
            "collision": self.collision,
            "off_track": self.off_track,
            "stalled": self.stalled,
            "nearest_opponent_m": self.nearest,
            "min_barrier": self.min_h,
            "barrier_slack": self.barrier_slack,
            "mpc_status": out.mpc.status if out is not None else "",
            "miqp_sides": tuple(np.asarray(plan.sides, dtype=int).tolist()) if plan is not None else (),
            "mpc_failures": stack.counters["mpc_failures"],
            "miqp_failures": stack.counters["miqp_failures"],
            "parked_checks": stack.counters["parked_checks"],
            "mpc_restarts": stack.counters["mpc_restarts"],
        }
        if timings:
            info["mpc_time_ms"] = 1e3 * self.mpc_time
            info["miqp_time_ms"] = 1e3 * self.miqp_time
        return info


@dataclass
class CarStep:
    """What one controlled car gets from one decision (or from a reset)."""

    observation: np.ndarray
    """Its observation after the decision (float32)."""
    reward: Any
    """Its reward: the float ``weights . vector`` (``reward_mode="scalar"``) or the float32 vector."""
    terminated: bool
    """It collided, left the track or stalled."""
    truncated: bool
    """The race reached its duration (and the car was not terminated)."""
    info: dict
    """Its info dictionary (``is_success`` added at the end of its episode)."""


class ControlledRace:
    """The race world plus one overtaking stack per controlled car (see the module docstring).

    ``n_cars`` controlled cars (car 0 first); ``speed_factors`` gives each car's speed
    factor (cycled; default: the stack config's). With ``remove_crashed`` a car that is
    terminated leaves the race (multi-car races); otherwise it stays where it is (the
    single-car environment ends its episode there anyway). The world and the controllers
    are built on the first :meth:`reset`.

    Every car's controller gets ``config.stack`` as it is. ``measured_barrier`` is the barrier that the
    reward's ``barrier_margin`` term, ``info["min_barrier"]``, the extended observation and the rendering
    measure (default: ``config.stack.mpc.barrier``). The PettingZoo adapter passes the barrier of the
    configuration without its multi-car layer: the layer widens the controllers' barrier
    (``race.heading_extent``) but not the one the rewards were defined with.
    """

    def __init__(self, config: EnvConfig, n_cars: int = 1, speed_factors=None, remove_crashed: bool = False,
                 measured_barrier=None):
        self.config = config
        self.measured_barrier = config.stack.mpc.barrier if measured_barrier is None else measured_barrier
        """The barrier of the rewards, the info, the extended observation and the rendering (see above)."""
        self.n_cars = int(n_cars)
        if speed_factors is None:
            self.speed_factors = None
        else:
            self.speed_factors = tuple(float(speed_factors[i % len(speed_factors)]) for i in range(self.n_cars))
        self.remove_crashed = bool(remove_crashed)
        self._weights = config.reward_weights.as_array()
        self._stall_steps = config.stall_steps  # a derived value, read at every control step
        self.track = None
        self.race = None
        self.stacks: list = []
        self.live: list[int] = []
        self.previous_gamma = np.full(self.n_cars, config.initial_gamma)
        self.outputs: list = [None] * self.n_cars
        """Each car's controller output of its last control step (MPC prediction, MIQP plan), for rendering."""
        self._opponents: list[np.ndarray] = [np.zeros((0, 3))] * self.n_cars
        self._sensed: list[np.ndarray] = self._opponents
        """What each car's controller and observation see of its opponents (without a sensor: the same list
        as the true rows)."""
        self._sensed_rows: list[np.ndarray] = self._opponents
        """What each car's controller gets: the seen rows, with the sensor's lateral-rate estimate as a
        fourth column when a sensor is on (:meth:`~sofar_env.stack.OvertakingStack.step`)."""
        self._sensed_ids: list[np.ndarray] = [np.zeros(0, int)] * self.n_cars
        self.sensors: list | None = None
        """One :class:`~sofar_env.sensing.Sensor` per car when ``race.sensor.enabled``."""
        self.slow_steps = np.zeros(self.n_cars, dtype=int)
        """Per car, the control steps it has been slower than ``stall_speed`` without interruption."""
        self._travel_time = None
        """The speed profile's travel time, for V2V rows of pace-predicting controllers (``race.v2v``)."""
        self.started = False
        """Whether a reset has ever succeeded (the world has been placed at least once)."""

    # ------------------------------------------------------------------ building
    def build(self) -> None:
        """Load the circuit, build the world and the controllers (done by the first :meth:`reset`)."""
        from .race import Race
        from .tracks import Track

        cfg = self.config
        try:  # all or nothing: a failure leaves the core unbuilt, and the next reset builds again
            self.track = cfg.track if isinstance(cfg.track, Track) else Track.load(cfg.track)
            self.race = Race(self.track, cfg.race, n_cars=self.n_cars)
            self.stacks = self._make_stacks(self.speed_factors)
        except BaseException:
            self.track, self.race, self.stacks = None, None, []
            raise
        if cfg.race.sensor.enabled:
            from .sensing import Sensor

            self.sensors = [Sensor(cfg.race.sensor, self.track.length, cfg.race.dt) for _ in range(self.n_cars)]
            self._sensed = [np.zeros((0, 3)) for _ in range(self.n_cars)]
            self._sensed_rows = [np.zeros((0, 4)) for _ in range(self.n_cars)]
        elif self.n_cars > 1 and cfg.race.lateral_rates != "off":  # the true rows plus the true lateral rates
            self._sensed_rows = [np.zeros((0, 4)) for _ in range(self.n_cars)]
        if cfg.race.v2v and self.n_cars > 1:
            from .v2v import TravelTime

            self._travel_time = TravelTime(self.track)

    def _make_stacks(self, speed_factors) -> list:
        """One controller per car, of ``config.stack`` as it is (the adapters resolve it, the multi-car defaults
        included: :mod:`sofar_env.configs.resolve`), with car i's speed factor ``speed_factors[i]`` when given."""
        from .stack import OvertakingStack

        cfg = self.config
        stack = cfg.stack
        if speed_factors is None:
            configs = [stack] * self.n_cars
        else:
            configs = [apply_overrides(stack, {"speed_factor": sf}) for sf in speed_factors]
        return [OvertakingStack(self.track, c, vehicle=cfg.race.vehicle) for c in configs]

    def set_speed_factors(self, speed_factors) -> None:
        """Give car i the speed factor ``speed_factors[i]`` (cycled) from the next :meth:`reset` on.

        The controllers are rebuilt with it (they are reset by every episode anyway).
        """
        factors = tuple(float(speed_factors[i % len(speed_factors)]) for i in range(self.n_cars))
        if self.race is None:
            self.build()
        self.stacks = self._make_stacks(factors)  # raises (changing nothing) for an invalid factor
        self.speed_factors = factors

    @property
    def built(self) -> bool:
        return self.race is not None

    @property
    def running(self) -> bool:
        """An episode is running: a reset succeeded and some car has neither terminated nor been truncated."""
        return bool(self.live)

    def not_running_message(self, call: str = "step()") -> str:
        """Why ``call`` is refused while no episode runs (the message of :class:`ResetNeeded`)."""
        if not self.started:
            return f"no episode is running (no reset() has succeeded yet): call reset() before {call}"
        return f"the episode has ended (every car terminated or was truncated): call reset() before {call}"

    # ------------------------------------------------------------------ episode
    def check_reset(self, **race_options: Any) -> None:
        """Raise ``ValueError`` if :meth:`reset` with these options would fail; changes nothing (but builds)."""
        if self.race is None:
            self.build()
        self.race.check_reset(**race_options)

    def reset(self, rng: np.random.Generator, **race_options: Any) -> dict[int, CarStep]:
        """Start an episode (``race_options`` go to :meth:`Race.reset`); each car's observation and info.

        Invalid options raise (``ValueError``) before anything changes. Past that check the running episode
        is over: should a later part fail, no episode runs until a reset succeeds.
        """
        self.check_reset(**race_options)
        self.live = []
        self.race.reset(rng, **race_options)
        for stack in self.stacks:
            stack.reset()
        if self.sensors is not None:
            for sensor in self.sensors:
                sensor.reset(rng)
        cars = list(range(self.n_cars))
        self.slow_steps[:] = 0
        self.previous_gamma[:] = self.config.initial_gamma
        self.outputs = [None] * self.n_cars
        bp = self.measured_barrier
        out = {}
        for i in cars:
            opp = self._opponents[i] = self.race.opponent_frenet(i)
            self._sense(i)
            tally = DecisionTally()
            tally.min_h = min_barrier(self.track, self.race.frenet[i], opp, bp)
            tally.gamma = self.previous_gamma[i]
            tally.nearest = self.race.nearest_distance(i)
            out[i] = CarStep(self._observe(i), None, False, False, self._info(tally, i))
        self.live = cars
        self.started = True
        return out

    def step(self, gammas: dict[int, float]) -> dict[int, CarStep]:
        """One decision of every live car: ``gammas`` maps each live car (and no other) to its validated gamma.

        Raises :class:`ResetNeeded` when no episode runs and ``ValueError`` when the cars of ``gammas`` are not
        the live cars, before anything changes.
        """
        if not self.live:
            raise ResetNeeded(self.not_running_message())
        if len(gammas) != len(self.live) or any(i not in gammas for i in self.live):
            raise ValueError(f"gammas must be given for exactly the live cars {self.live}, got cars {sorted(gammas)}")
        race, track = self.race, self.track
        bp = self.measured_barrier
        live = list(self.live)
        tallies = {i: DecisionTally() for i in live}
        running = list(live)
        controls = np.zeros((self.n_cars, 2))
        stall_steps = self._stall_steps
        for _ in range(self.config.decision_interval):
            controls[:] = 0.0
            outs = {}
            rows = self._v2v_rows() if self._travel_time is not None else self._sensed_rows
            for i in running:
                gamma = gammas[i]
                assert GAMMA_MIN <= gamma <= GAMMA_MAX, "gamma is validated by parse_gamma at the API boundary"
                outs[i] = self.stacks[i].step(race.frenet[i], rows[i], gamma)
                controls[i] = outs[i].u
            profile = {i: track.speed(float(race.frenet[i, 0])) for i in running}
            events = race.step(controls)
            for i in range(self.n_cars):
                self._opponents[i] = race.opponent_frenet(i)
                self._sense(i)
            for i in running:
                tallies[i].add(race, i, outs[i], events[i], self._opponents[i], profile[i],
                               self.previous_gamma[i], bp)
                self.previous_gamma[i] = gammas[i]
                self.outputs[i] = outs[i]
                slow = race.frenet[i, 3] < self.config.stall_speed
                self.slow_steps[i] = self.slow_steps[i] + 1 if slow else 0
                if stall_steps is not None and self.slow_steps[i] >= stall_steps and not tallies[i].terminated:
                    tallies[i].stalled = True
            crashed = [i for i in running if tallies[i].terminated]
            for i in crashed:
                running.remove(i)
                if self.remove_crashed:
                    race.deactivate(i)
            if crashed and self.remove_crashed:  # the others no longer see the crashed cars
                for i in range(self.n_cars):
                    self._opponents[i] = race.opponent_frenet(i)
                    self._sense(i, again=True)
            if not running or race.truncated:
                break
        truncate_all = race.truncated
        out = {}
        for i in live:
            tally = tallies[i]
            terminated = tally.terminated
            truncated = truncate_all and not terminated
            info = self._info(tally, i)
            if terminated or truncated:
                info["is_success"] = not terminated
            out[i] = CarStep(self._observe(i, tally), self._reward(tally.vector), terminated,
                             truncated, info)
        self.live = [i for i in live if not (out[i].terminated or out[i].truncated)]
        return out

    # ------------------------------------------------------------------ per car
    def _sense(self, car: int, again: bool = False) -> None:
        """Update what car ``car`` sees of its opponents: the sensor's (s, n, v) estimates of the true rows
        (and, for its controller, the estimated lateral rates).

        Without a sensor the seen rows are the true rows (the same list); in a multi-car race the
        controller's rows also carry the true lateral rates, unless ``race.lateral_rates`` is "off".
        Collisions, track limits, overtakes and the barrier-margin reward are always judged on the
        true state. ``again``: the field changed within the same control step (a car left the race);
        the sensor is not advanced a second time, the rows of the cars that left are dropped.
        """
        if self.sensors is None:
            if self._sensed_rows is not self._opponents:  # a multi-car race with race.lateral_rates on
                rows = self._opponents[car]
                self._sensed_rows[car] = np.column_stack([rows, self.race.opponent_lateral_rates(car)])
            return
        if again:
            keep = np.isin(self._sensed_ids[car], self.race.opponent_ids(car))
            self._sensed[car] = self._sensed[car][keep]
            self._sensed_rows[car] = self._sensed_rows[car][keep]
            self._sensed_ids[car] = self._sensed_ids[car][keep]
            return
        ids = self.race.opponent_ids(car)
        rows = self.sensors[car].measure(self._opponents[car], ids)
        self._sensed_rows[car] = rows
        self._sensed[car] = np.ascontiguousarray(rows[:, :3])
        self._sensed_ids[car] = ids

    def _observe(self, car: int, tally: DecisionTally | None = None) -> np.ndarray:
        """Car ``car``'s observation from what it senses (the layout of ``EnvConfig.observation``); ``tally``: the
        decision just recorded, whose barrier value the extended layout reuses where it was measured on the very
        rows the car senses (no sensor) with the same barrier (the car has not moved since)."""
        if self.config.observation == "paper":
            return observe(self.race, car, self._sensed[car])
        rows = self._sensed_rows[car]
        same = tally is not None and tally.min_h_of is not None and tally.min_h_of[0] is rows \
            and tally.min_h_of[1] is self.measured_barrier
        return observe(self.race, car, rows, "extended", self.measured_barrier, tally.min_h if same else None)

    def _v2v_rows(self) -> list[np.ndarray]:
        """Each car's opponent rows for its controller under ``race.v2v`` (:mod:`sofar_env.v2v`): for every other
        controlled car whose last MPC step solved, the more cautious of its sensed speed and the speed that
        reproduces its published plan (the smaller for a car ahead, the larger for a car behind)."""
        from .v2v import published_advance, speed_for_advance

        race, dt = self.race, self.config.race.dt
        advances: dict[tuple[int, float], float] = {}
        out_rows = []
        for car in range(self.n_cars):
            rows = self._sensed_rows[car]
            ids = self._sensed_ids[car] if self.sensors is not None else race.opponent_ids(car)
            cfg = self.stacks[car].config
            horizon = float(cfg.mpc.time_grid()[-1])
            travel = self._travel_time if cfg.pace_prediction else None
            new = None
            for r, rid in enumerate(np.asarray(ids).tolist()):
                c = -1 - rid
                plan = self.outputs[c] if rid < 0 else None
                if plan is None or plan.mpc.status != "solved" or not race.active[c]:
                    continue
                key = (c, horizon)
                if key not in advances:
                    x = plan.mpc.x_pred
                    advances[key] = published_advance(self.stacks[c].plan_times, x[:, 0], x[-1, 3],
                                                      dt, horizon)
                if new is None:
                    new = np.array(rows, dtype=float)
                shared = speed_for_advance(travel, float(new[r, 0]), advances[key], horizon)
                ahead = float(self.track.gap(new[r, 0], race.frenet[car, 0])) >= 0.0
                new[r, 2] = min(new[r, 2], shared) if ahead else max(new[r, 2], shared)
            out_rows.append(rows if new is None else new)
        return out_rows

    def _reward(self, vector: np.ndarray):
        if self.config.reward_mode == "vector":
            return vector.astype(np.float32)
        return scalarize(vector, self._weights)

    def _info(self, tally: DecisionTally, car: int) -> dict:
        return tally.info(self.race, self.stacks[car], car, timings=self.config.timing_info)

    def render_frame(self, renderer, car: int):
        """Draw car ``car``'s view with ``renderer`` (:class:`~sofar_env.render.Renderer`)."""
        seen = self._sensed[car] if self.sensors is not None else None
        return renderer.draw(self.race, self.outputs[car], gamma=float(self.previous_gamma[car]), car=car, seen=seen)
