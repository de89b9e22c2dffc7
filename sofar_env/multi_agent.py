"""PettingZoo parallel environment: several cars, each driven by its own overtaking stack.

A thin adapter over the same simulation core as the Gymnasium environment
(:class:`~sofar_env.core.ControlledRace`), with ``n_agents`` controlled cars and no scripted opponents:
every car's opponents are the other active cars (``race.opponent_frenet(car)``).
Each agent's action is its own gamma; observation, action, reward terms and info
are those of :class:`~sofar_env.env.SOfARRaceEnv`, per car (wall-clock solve times
only with ``timing_info=True``). Cars start
``race.car_spacing`` (40 m) apart, car 0 in front on the raceline, the others at
the lateral offsets ``race.car_offsets``. Give them different ``speed_factors`` for
overtakes to happen.

A car that collides, leaves the track or stalls (the stall rule of
:mod:`sofar_env.core`: slower than ``stall_speed`` for ``stall_seconds``, per car)
terminates and leaves the race (it stops and no longer counts as an obstacle); in a
collision between two cars both terminate. All remaining cars are truncated at the race duration.

``reset(options=...)`` accepts ``start_s`` and ``start_speed``; other keys are
ignored with a logged warning (PettingZoo's API test passes arbitrary options).
"""

from __future__ import annotations

import logging
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from gymnasium import spaces
from gymnasium.utils import seeding
from pettingzoo import ParallelEnv

from .config import OBJECTIVE_NAMES, EnvConfig, apply_overrides, make_env_config
from .constants import GAMMA_MAX, GAMMA_MIN
from .core import ControlledRace, parse_gamma

__all__ = ["SOfARParallelEnv", "parallel_env"]

logger = logging.getLogger(__name__)

_MA_RESET_OPTIONS = ("start_s", "start_speed")


class SOfARParallelEnv(ParallelEnv):
    """Multi-car race; see the module docstring. Agents are named ``car_0`` ... ``car_{n-1}``."""

    metadata = {"name": "sofar_race_v0", "render_modes": ["human", "rgb_array"], "render_fps": 10,
                "is_parallelizable": True}

    def __init__(self, n_agents: int = 3, config: EnvConfig | Mapping[str, Any] | None = None,
                 render_mode: str | None = None, speed_factors: Sequence[float] | None = None, **kwargs: Any):
        if int(n_agents) < 1:
            raise ValueError(f"n_agents must be >= 1, got {n_agents}")
        cfg = make_env_config(config, **kwargs)
        if cfg.n_opponents and ("n_opponents" in kwargs or (isinstance(config, Mapping) and "n_opponents" in config)):
            raise ValueError("the multi-agent environment has no scripted opponents: the other cars are the opponents")
        self.config = apply_overrides(cfg, {"race": {"opponents": {"n_opponents": 0}}})
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be one of {self.metadata['render_modes']} or None, got {render_mode!r}")
        self.render_mode = render_mode
        self.n_agents = int(n_agents)
        self.possible_agents = [f"car_{i}" for i in range(self.n_agents)]
        self.agents: list[str] = []
        self._index = {a: i for i, a in enumerate(self.possible_agents)}
        if speed_factors is None:
            speed_factors = (self.config.stack.speed_factor,)
        self.core = ControlledRace(self.config, n_cars=self.n_agents, speed_factors=speed_factors,
                                   remove_crashed=True)
        """The simulation core: the race world and one controller per car."""
        self.speed_factors = self.core.speed_factors
        self._observation_spaces = {a: spaces.Box(-1.0, 1.0, (12,), np.float32) for a in self.possible_agents}
        self._action_spaces = {a: spaces.Box(GAMMA_MIN, GAMMA_MAX, (1,), np.float32) for a in self.possible_agents}
        self.objective_names = OBJECTIVE_NAMES
        self._np_random = None
        self._renderer = None

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

    # ------------------------------------------------------------------ API
    def reset(self, seed: int | None = None, options: dict | None = None):
        options = dict(options or {})
        ignored = sorted(set(options) - set(_MA_RESET_OPTIONS))
        if ignored:
            logger.warning("ignoring unknown reset option(s) %s; valid: %s", ignored, ", ".join(_MA_RESET_OPTIONS))
        race_options = {k: options[k] for k in _MA_RESET_OPTIONS if k in options}
        self.core.check_reset(**race_options)  # a failed reset leaves the env as it was
        if seed is not None or self._np_random is None:
            self._np_random, _ = seeding.np_random(seed)
        first = self.core.reset(self._np_random, **race_options)
        self.agents = list(self.possible_agents)
        observations = {a: first[self._index[a]].observation for a in self.agents}
        infos = {a: first[self._index[a]].info for a in self.agents}
        if self.render_mode == "human":
            self.render()
        return observations, infos

    def step(self, actions: Mapping[str, Any]):
        if not self.core.built:
            raise RuntimeError("call reset() before step()")
        missing = [a for a in self.agents if a not in actions]
        if missing:
            raise ValueError(f"no action for live agent(s) {missing}")
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
        if not self.core.built:
            raise RuntimeError("call reset() before render()")
        if self._renderer is None:
            from .render import Renderer

            self._renderer = Renderer(self.track, self.config.race.vehicle, self.config.stack.mpc.barrier,
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
    cycled) and every key of :func:`~sofar_env.config.make_env_config` except ``n_opponents``.
    """
    return SOfARParallelEnv(n_agents=n_agents, track=track, **kwargs)
