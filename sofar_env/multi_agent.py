"""PettingZoo parallel environment: several cars, each driven by its own overtaking stack.

A thin adapter over the same :class:`~sofar_env.race.Race` as the Gymnasium
environment, with ``n_cars = n_agents`` controlled cars and no scripted opponents:
every car's opponents are the other active cars (``race.opponent_frenet(car)``).
Each agent's action is its own gamma; observation, action, reward terms and info
are those of :class:`~sofar_env.env.SOfARRaceEnv`, per car (PettingZoo's seed
test compares infos exactly: run it with ``timing_info=False``). Cars start
``race.car_spacing`` (40 m) apart, car 0 in front on the raceline, the others at
the lateral offsets ``race.car_offsets``. Give them different ``speed_factors`` for
overtakes to happen.

A car that collides or leaves the track terminates and leaves the race (it stops
and no longer counts as an obstacle); in a collision between two cars both
terminate. All remaining cars are truncated at the race duration.

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
from .env import GAMMA_MAX, GAMMA_MIN, DecisionTally, min_barrier, parse_gamma
from .observation import observe
from .rewards import scalarize

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
        self.speed_factors = tuple(float(speed_factors[i % len(speed_factors)]) for i in range(self.n_agents))
        self._observation_spaces = {a: spaces.Box(-1.0, 1.0, (12,), np.float32) for a in self.possible_agents}
        self._action_spaces = {a: spaces.Box(GAMMA_MIN, GAMMA_MAX, (1,), np.float32) for a in self.possible_agents}
        self.objective_names = OBJECTIVE_NAMES
        self._weights = self.config.reward_weights.as_array()
        self.track = None
        self.race = None
        self.stacks = []
        self._np_random = None
        self._previous_gamma = np.full(self.n_agents, self.config.initial_gamma)
        self._outputs: list = [None] * self.n_agents
        self._renderer = None

    def observation_space(self, agent: str) -> spaces.Box:
        return self._observation_spaces[agent]

    def action_space(self, agent: str) -> spaces.Box:
        return self._action_spaces[agent]

    # ------------------------------------------------------------------ building
    def _build(self) -> None:
        from .race import Race
        from .stack import OvertakingStack
        from .tracks import Track

        cfg = self.config
        self.track = Track.load(cfg.track)
        self.race = Race(self.track, cfg.race, n_cars=self.n_agents)
        self.stacks = [
            OvertakingStack(self.track, apply_overrides(cfg.stack, {"speed_factor": sf}), vehicle=cfg.race.vehicle)
            for sf in self.speed_factors
        ]

    # ------------------------------------------------------------------ API
    def reset(self, seed: int | None = None, options: dict | None = None):
        if seed is not None or self._np_random is None:
            self._np_random, _ = seeding.np_random(seed)
        options = dict(options or {})
        ignored = sorted(set(options) - set(_MA_RESET_OPTIONS))
        if ignored:
            logger.warning("ignoring unknown reset option(s) %s; valid: %s", ignored, ", ".join(_MA_RESET_OPTIONS))
        if self.race is None:
            self._build()
        self.race.reset(self._np_random, **{k: options[k] for k in _MA_RESET_OPTIONS if k in options})
        for stack in self.stacks:
            stack.reset()
        self.agents = list(self.possible_agents)
        self._previous_gamma[:] = self.config.initial_gamma
        self._outputs = [None] * self.n_agents
        bp = self.config.stack.mpc.barrier
        observations, infos = {}, {}
        for agent in self.agents:
            i = self._index[agent]
            opp = self.race.opponent_frenet(i)
            tally = DecisionTally()
            tally.min_h = min_barrier(self.track, self.race.frenet[i], opp, bp)
            tally.gamma = self._previous_gamma[i]
            tally.nearest = self.race.nearest_distance(i)
            observations[agent] = observe(self.race, i, opp)
            infos[agent] = tally.info(self.race, self.stacks[i], i, timings=self.config.timing_info)
        if self.render_mode == "human":
            self.render()
        return observations, infos

    def step(self, actions: Mapping[str, Any]):
        if self.race is None:
            raise RuntimeError("call reset() before step()")
        race, track = self.race, self.track
        live = [self._index[a] for a in self.agents]
        missing = [a for a in self.agents if a not in actions]
        if missing:
            raise ValueError(f"no action for live agent(s) {missing}")
        gammas = {i: parse_gamma(actions[self.possible_agents[i]]) for i in live}
        tallies = {i: DecisionTally() for i in live}
        bp = self.config.stack.mpc.barrier
        running = list(live)
        for _ in range(self.config.decision_interval):
            controls = np.zeros((self.n_agents, 2))
            outs = {}
            for i in running:
                outs[i] = self.stacks[i].step(race.frenet[i], race.opponent_frenet(i), gammas[i])
                controls[i] = outs[i].u
            profile = {i: track.speed(race.frenet[i, 0]) for i in running}
            events = race.step(controls)
            for i in running:
                tallies[i].add(race, i, outs[i], events[i], race.opponent_frenet(i), profile[i],
                               self._previous_gamma[i], bp)
                self._previous_gamma[i] = gammas[i]
                self._outputs[i] = outs[i]
            for i in [i for i in running if tallies[i].terminated]:
                race.deactivate(i)
                running.remove(i)
            if not running or race.truncated:
                break
        truncate_all = race.truncated
        observations, rewards, terminations, truncations, infos = {}, {}, {}, {}, {}
        for i in live:
            agent = self.possible_agents[i]
            tally = tallies[i]
            observations[agent] = observe(race, i)
            if self.config.reward_mode == "vector":
                rewards[agent] = tally.vector.astype(np.float32)
            else:
                rewards[agent] = scalarize(tally.vector, self._weights)
            terminations[agent] = tally.terminated
            truncations[agent] = truncate_all and not tally.terminated
            info = tally.info(race, self.stacks[i], i, timings=self.config.timing_info)
            if terminations[agent] or truncations[agent]:
                info["is_success"] = not terminations[agent]
            infos[agent] = info
        self.agents = [a for a in self.agents if not (terminations[a] or truncations[a])]
        if self.render_mode == "human":
            self.render()
        return observations, rewards, terminations, truncations, infos

    def render(self):
        if self.render_mode is None:
            logger.warning("render() called without a render_mode")
            return None
        if self.race is None:
            raise RuntimeError("call reset() before render()")
        if self._renderer is None:
            from .render import Renderer

            self._renderer = Renderer(self.track, self.config.race.vehicle, self.config.stack.mpc.barrier,
                                      fps=self.metadata["render_fps"])
        car = self._index[self.agents[0]] if self.agents else 0
        frame = self._renderer.draw(self.race, self._outputs[car], gamma=float(self._previous_gamma[car]), car=car)
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
