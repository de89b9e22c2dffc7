"""PettingZoo parallel environment: several cars, each driven by its own overtaking stack.

A thin adapter over the same simulation core as the Gymnasium environment
(:class:`~sofar_env.core.ControlledRace`), with ``n_agents`` controlled cars and, optionally,
``n_opponents`` scripted opponents (default none): every car's opponents are the other active cars and
the scripted ones (``race.opponent_frenet(car)``).
Each agent's action is its own gamma; observation, action, reward terms and info
are those of :class:`~sofar_env.env.SOfARRaceEnv`, per car (wall-clock solve times
only with ``timing_info=True``).

**Start.** A rolling start from a grid two abreast and staggered (:class:`~sofar_env.race.RaceConfig`,
:meth:`~sofar_env.race.Race.grid_slot`): car 0 on pole at the drawn start arc length,
``race.grid_lateral_offset`` (2 m) left of the raceline; car 1 ``race.grid_stagger`` (12 m) behind it
and 2 m right; each further row of two ``race.grid_row_spacing`` (24 m) behind the previous one (so
consecutive cars are 12 m apart, alternately left and right); a car alone in the last row starts on the
raceline. Offsets are moved inwards where a footprint would come within 0.5 m of an edge. Every car
starts at the same drawn fraction (``race.start_speed_fraction``) of the speed profile at its own place.

**Pace.** At every reset each car's speed factor (its speed reference as a fraction of the speed
profile) is drawn uniformly in ``race.pace_range`` (default U(0.9, 1.0)) from the environment's
random generator, so the same seed gives the same factors and faster cars meet slower ones; the
factors of the episode are in ``env.speed_factors``. ``speed_factors=`` (one per car, cycled) or
``speed_factor=`` fixes them instead.

Overtakes between controlled cars are counted for the passer only (``info["overtakes"]``): car i
is credited once when a car that was ahead of it falls ``race.opponents.overtake_threshold`` (2 m)
behind; it is credited again only after that car got ahead once more.

A car that collides, leaves the track or stalls (the stall rule of
:mod:`sofar_env.core`: slower than ``stall_speed`` for ``stall_seconds``, per car)
terminates and leaves the race (it stops and no longer counts as an obstacle); in a
collision between two cars both terminate. All remaining cars are truncated at the race duration.
Each car's controller predicts the others from what it senses; with ``race={"v2v": True}`` the cars
also share their MPC plans and predict each other from them (:mod:`sofar_env.v2v`). Each car's
passing-side planner keeps the side of every car alongside it (within ``race.side_lock`` = 6 m along the
track; ``stack.miqp.alongside_gap``, :mod:`sofar_env.planning.miqp`): two cars alongside do not plan
through each other. Each car's MPC restarts from a cold guess when its warm-started solve needs more
DCBF slack than ``race.mpc_restart_slack`` = 0.05, and keeps the solution with less slack
(``stack.mpc.restart_slack``, :mod:`sofar_env.control.mpc.rti`): a plan that passed a car on one side no
longer drags the next plan across that car after the side changed. Each car's MPC also gets the other
cars' lateral rates and predicts them moving across the track; its passing-side planner sees them where
they are (``race.lateral_rates`` = "mpc"; "all" also gives the rates to the planners, "off" to no one).
Each car's barrier widens its lateral semi-axis with the car's own heading error to the track and the
other car's course angle, whose sine is its lateral rate over its speed (``race.heading_extent`` = 2.45 m,
half the car length, times a smooth ``|sin|`` of each; ``stack.mpc.barrier.heading_extent``,
:mod:`sofar_env.control.barrier`): a car turned in a chicane reaches further across the track than the
ellipse of aligned cars covers.
The ``scenario`` key of the interactive world (:mod:`sofar_env.scenarios`) applies here too.
These multi-car defaults are one layer of the configuration's resolution
(:func:`~sofar_env.configs.resolve.multi_car_overrides`), applied after the world and the ``stack`` preset and
before the user's own keys, which win: ``stack={"mpc": {"barrier": {"heading_extent": 0.0}}}`` gives 0.
``env.config`` is the resolved configuration, what every car's controller gets.

**Scripted opponents.** ``n_opponents=k`` (or the reset option) adds the scripted field of the
single-car environment at pace ratio ``rho`` (the config's ``race.opponents.rho``, or the reset
option), starting at its configured gaps ahead of the pole. It is not respawned: the controlled cars
pass it and lap it, and each pass is credited to the passer (:mod:`sofar_env.race`). With
``scenario="interactive"`` the scripted cars race back: each defends against the nearest controlled
car behind it and keeps clear of every controlled car alongside.

``reset(options=...)`` accepts ``start_s``, ``start_speed``, ``rho`` and ``n_opponents``; other keys are
ignored with a logged warning (PettingZoo's API test passes arbitrary options). ``n_agents`` must be an
integer >= 1 (a :class:`~sofar_env.errors.ConfigError` otherwise). ``step(actions)`` takes one action for
each agent of ``env.agents`` and no other (an unknown agent, or one that has terminated or been truncated,
is a ``ValueError``); with no agent left, or before the first successful reset, it raises
:class:`~sofar_env.errors.ResetNeeded` (a ``RuntimeError``). A call that raises changes nothing.

**AEC.** :func:`env` and :func:`raw_env` give the same race as PettingZoo's agent-environment-cycle
API (``pettingzoo.utils.parallel_to_aec``; :func:`env` with PettingZoo's order enforcement, :func:`raw_env`
without): the cars act one after the other, and the race advances once all live cars have acted.

**Copies.** ``copy.deepcopy``, ``pickle`` and ``get_state()`` / ``set_state()`` work as for the Gymnasium
environment (:class:`~sofar_env.env.SOfARRaceEnv`, "Copies and saved states"; :mod:`sofar_env.snapshot`):
a copy or a restored state continues to the bit as the original under the same actions.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from gymnasium import spaces
from gymnasium.utils import seeding
from pettingzoo import AECEnv, ParallelEnv
from pettingzoo.utils import parallel_to_aec
from pettingzoo.utils.conversions import parallel_to_aec_wrapper

from .config import OBJECTIVE_NAMES, EnvConfig
from .configs.resolve import resolve_env_config
from .constants import GAMMA_MAX, GAMMA_MIN
from .core import ControlledRace, parse_gamma
from .domains import is_integer
from .errors import ConfigError, ResetNeeded
from .observation import observation_size
from .race import MAX_SPEED_FACTOR, _is_real
from .snapshot import Snapshots

__all__ = ["SOfARParallelEnv", "parallel_env", "env", "raw_env"]

logger = logging.getLogger(__name__)

_MA_RESET_OPTIONS = ("start_s", "start_speed", "rho", "n_opponents")


class SOfARParallelEnv(Snapshots, ParallelEnv):
    """Multi-car race; see the module docstring. Agents are named ``car_0`` ... ``car_{n-1}``."""

    metadata = {"name": "sofar_race_v0", "render_modes": ["human", "rgb_array"], "render_fps": 10,
                "is_parallelizable": True}

    def __init__(self, n_agents: int = 3, config: EnvConfig | Mapping[str, Any] | None = None,
                 render_mode: str | None = None, speed_factors: Sequence[float] | None = None, **kwargs: Any):
        if not (is_integer(n_agents) and n_agents >= 1):
            raise ConfigError(f"n_agents must be an integer >= 1, got {n_agents!r} ({type(n_agents).__name__})")
        # the multi-car defaults (no scripted opponents, the controllers' settings of race.side_lock, lateral_rates,
        # mpc_restart_slack, heading_extent) apply as a layer below the user's keys
        self.config = resolve_env_config(config, kwargs, multi_car=True)
        """The resolved configuration, the multi-car defaults included (what the cars' controllers get)."""
        measured_barrier = resolve_env_config(config, kwargs).stack.mpc.barrier  # without the multi-car layer
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be one of {self.metadata['render_modes']} or None, got {render_mode!r}")
        self.render_mode = render_mode
        self.n_agents = int(n_agents)
        self.possible_agents = [f"car_{i}" for i in range(self.n_agents)]
        self.agents: list[str] = []
        self._index = {a: i for i, a in enumerate(self.possible_agents)}
        if speed_factors is None and "speed_factor" in kwargs:
            speed_factors = (self.config.stack.speed_factor,)
        self.draw_pace = speed_factors is None
        """Whether each reset draws the cars' speed factors in ``race.pace_range``."""
        if speed_factors is not None and not (len(speed_factors) and all(
                _is_real(f) and 0.0 < f <= MAX_SPEED_FACTOR for f in speed_factors)):
            raise ValueError(f"speed_factors must be numbers in (0, {MAX_SPEED_FACTOR:g}], one per car (cycled), "
                             f"got {speed_factors!r}")
        self.core = ControlledRace(self.config, n_cars=self.n_agents, speed_factors=speed_factors,
                                   remove_crashed=True, measured_barrier=measured_barrier)
        """The simulation core: the race world and one controller per car."""
        obs_size = observation_size(self.config.observation)
        self._observation_spaces = {a: spaces.Box(-1.0, 1.0, (obs_size,), np.float32) for a in self.possible_agents}
        self._action_spaces = {a: spaces.Box(GAMMA_MIN, GAMMA_MAX, (1,), np.float32) for a in self.possible_agents}
        self.objective_names = OBJECTIVE_NAMES
        self._np_random = None
        self._renderer = None

    _state_attributes = ("core", "_np_random", "agents")  # what get_state() saves

    def observation_space(self, agent: str) -> spaces.Box:
        return self._observation_spaces[agent]

    def action_space(self, agent: str) -> spaces.Box:
        return self._action_spaces[agent]

    @property
    def track(self):
        return self.core.track

    @property
    def race(self):
        return self.core.race

    @property
    def stacks(self) -> list:
        return self.core.stacks

    @property
    def speed_factors(self) -> tuple[float, ...] | None:
        """Each car's speed factor in the current episode (None before the first reset when they are drawn)."""
        return self.core.speed_factors

    # ------------------------------------------------------------------ API
    def reset(self, seed: int | None = None, options: dict | None = None):
        options = dict(options or {})
        ignored = sorted(set(options) - set(_MA_RESET_OPTIONS))
        if ignored:
            logger.warning("ignoring unknown reset option(s) %s; valid: %s", ignored, ", ".join(_MA_RESET_OPTIONS))
        race_options = {k: options[k] for k in _MA_RESET_OPTIONS if k in options}
        self.core.check_reset(**race_options)  # a failed reset leaves the env as it was
        self.agents = []  # past the checks: should anything below fail, no episode runs
        if seed is not None or self._np_random is None:
            self._np_random, _ = seeding.np_random(seed)
        if self.draw_pace:
            lo, hi = self.config.race.pace_range
            self.core.set_speed_factors(self._np_random.uniform(lo, hi, self.n_agents).tolist())
        first = self.core.reset(self._np_random, **race_options)
        self.agents = list(self.possible_agents)
        observations = {a: first[self._index[a]].observation for a in self.agents}
        infos = {a: first[self._index[a]].info for a in self.agents}
        if self.render_mode == "human":
            self.render()
        return observations, infos

    def step(self, actions: Mapping[str, Any]):
        """One decision of every agent in the race: ``actions`` maps each agent of ``self.agents`` (and no other)
        to its gamma. Raises :class:`~sofar_env.errors.ResetNeeded` (a ``RuntimeError``) when no episode runs
        (before the first successful reset, or once every agent has terminated or been truncated) and
        ``ValueError`` for a missing action, an action for an agent that is not in the race (unknown, or gone:
        terminated or truncated) or an invalid gamma; a call that raises changes nothing."""
        if not self.agents:
            raise ResetNeeded(self.core.not_running_message())
        missing = [a for a in self.agents if a not in actions]
        if missing:
            raise ValueError(f"no action for live agent(s) {missing}")
        extra = [a for a in actions if a not in self.agents]
        if extra:
            gone = [a for a in extra if a in self._index]
            unknown = [a for a in extra if a not in self._index]
            raise ValueError("actions for agents not in the race: "
                             + "; ".join(([f"unknown agent(s) {unknown} (agents: {self.possible_agents})"] if unknown
                                          else []) + ([f"{gone} have terminated or been truncated"] if gone else []))
                             + f"; give actions for exactly env.agents = {self.agents}")
        gammas = {self._index[a]: parse_gamma(actions[a]) for a in self.agents}
        results = self.core.step(gammas)
        names = {i: self.possible_agents[i] for i in results}
        observations = {names[i]: r.observation for i, r in results.items()}
        rewards = {names[i]: r.reward for i, r in results.items()}
        terminations = {names[i]: r.terminated for i, r in results.items()}
        truncations = {names[i]: r.truncated for i, r in results.items()}
        infos = {names[i]: r.info for i, r in results.items()}
        self.agents = [a for a in self.agents if not (terminations[a] or truncations[a])]
        if self.render_mode == "human":
            self.render()
        return observations, rewards, terminations, truncations, infos

    def render(self):
        if self.render_mode is None:
            logger.warning("render() called without a render_mode")
            return None
        if not self.core.started:
            raise ResetNeeded(self.core.not_running_message("render()"))
        if self._renderer is None:
            from .render import Renderer

            self._renderer = Renderer(self.track, self.config.race.vehicle, self.core.measured_barrier,
                                      fps=self.metadata["render_fps"])
        car = self._index[self.agents[0]] if self.agents else 0
        frame = self.core.render_frame(self._renderer, car)
        if self.render_mode == "human":
            self._renderer.show(frame)
            return None
        return frame

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None


def parallel_env(track: str = "LagunaSeca", n_agents: int = 3, **kwargs: Any) -> SOfARParallelEnv:
    """A :class:`SOfARParallelEnv` on ``track`` with ``n_agents`` cars.

    Other keyword arguments: ``config``, ``render_mode``, ``speed_factors`` (one per car,
    cycled; default: drawn per episode in ``race.pace_range``) and every key of
    :func:`~sofar_env.config.make_env_config` except ``n_opponents``.
    """
    return SOfARParallelEnv(n_agents=n_agents, track=track, **kwargs)


def raw_env(track: str = "LagunaSeca", n_agents: int = 3, **kwargs: Any) -> AECEnv:
    """The race of :func:`parallel_env` (same arguments) as a PettingZoo ``AECEnv``, without wrappers."""
    return parallel_to_aec_wrapper(parallel_env(track=track, n_agents=n_agents, **kwargs))


def env(track: str = "LagunaSeca", n_agents: int = 3, **kwargs: Any) -> AECEnv:
    """The race of :func:`parallel_env` (same arguments) as a PettingZoo ``AECEnv``
    (``pettingzoo.utils.parallel_to_aec``: with PettingZoo's order enforcement)."""
    return parallel_to_aec(parallel_env(track=track, n_agents=n_agents, **kwargs))
