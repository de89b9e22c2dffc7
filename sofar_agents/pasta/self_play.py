"""Self-play: the PettingZoo race presented to PASTA as a vector of per-car environments.

:class:`RaceVectorEnv` holds one or more races (:class:`sofar_env.multi_agent.SOfARParallelEnv`,
in ``reward_mode="vector"``) and shows every car of every race as one slot of a Gymnasium-style
vector environment (``num_envs = races x cars``, slot ``j * cars + i`` is car ``i`` of race ``j``).
One PASTA agent drives all slots, so the gamma policy is parameter-shared; each slot keeps its
own observation, reward vector, return and per-episode preference, exactly like the envs of a
single-car vector env, and PASTA's rollout and update code runs unchanged.

**When a car's race ends early.** PASTA's rollouts have one transition per slot and step and no
mask, so a race ends for *all* its cars as soon as *any* of them terminates (collision, leaving
the track, stalling): the terminated cars' transitions are terminal (no bootstrap), the other
cars' are *truncated* (bootstrapped from the value of their last observation, which estimates
what the rest of the race would have been worth) and have no ``is_success`` in their final info.
The race is then reset at once (same-step autoreset, the next episode's first observation takes
the slot). At the race duration every car is truncated as in the environment. Evaluation
(``eval/table.py --multi-agent``) uses the environment's own rule instead: the other cars race on.

Seeding: ``reset(seed=s)`` resets race ``j`` with ``s + j``; the automatic resets continue each
race's own generator, so a seeded run is deterministic. Steps are counted per car decision
(``num_envs`` per vector step).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

__all__ = ["RaceVectorEnv", "make_self_play_race"]


def make_self_play_race(track: Any, n_cars: int, env_kwargs: dict[str, Any]) -> Any:
    """One training race: :func:`sofar_env.multi_agent.parallel_env` in vector-reward mode.

    A module-level function, so ``functools.partial(make_self_play_race, ...)`` is a picklable factory.
    """
    from sofar_env.multi_agent import parallel_env

    return parallel_env(track, n_agents=n_cars, reward_mode="vector", **env_kwargs)


class RaceVectorEnv:
    """Races of controlled cars as one vector env of ``races x cars`` slots (see the module docstring).

    Args:
        race_fns: one factory per race, each returning a PettingZoo parallel env with a fixed
            ``possible_agents`` list, vector rewards (``config.reward_mode == "vector"``) and the same
            observation and action spaces for every car.
    """

    metadata = {"autoreset_mode": gym.vector.AutoresetMode.SAME_STEP}

    def __init__(self, race_fns: Sequence[Callable[[], Any]]):
        if not race_fns:
            raise ValueError("RaceVectorEnv needs at least one race factory")
        self.races = [fn() for fn in race_fns]
        first = self.races[0]
        self.agents = [list(r.possible_agents) for r in self.races]
        for j, race in enumerate(self.races):
            mode = getattr(getattr(race, "config", None), "reward_mode", None)
            if mode != "vector":
                raise ValueError(f"race {j} must be built with reward_mode='vector' (got {mode!r})")
        self.single_observation_space = first.observation_space(first.possible_agents[0])
        self.single_action_space = first.action_space(first.possible_agents[0])
        self.objective_names = tuple(first.objective_names)
        k = len(self.objective_names)
        self.reward_space = spaces.Box(-np.inf, np.inf, (k,), np.float32)
        self.num_envs = sum(len(a) for a in self.agents)
        self._offsets = np.cumsum([0] + [len(a) for a in self.agents])
        self.obs_dim = int(np.prod(self.single_observation_space.shape))

    # ------------------------------------------------------------------ helpers
    def _slots(self, j: int) -> range:
        return range(int(self._offsets[j]), int(self._offsets[j + 1]))

    def get_attr(self, name: str) -> list[Any]:
        """``[getattr(self, name)]`` per slot (what the training helpers read: ``objective_names``, ``reward_space``)."""
        return [getattr(self, name)] * self.num_envs

    # ------------------------------------------------------------------ API
    def reset(self, seed: int | None = None, options: dict | None = None) -> tuple[np.ndarray, dict]:
        """Reset every race (race ``j`` with ``seed + j``); the stacked observations ``(num_envs, obs_dim)``."""
        obs = np.zeros((self.num_envs, self.obs_dim), np.float32)
        for j, race in enumerate(self.races):
            first, _ = race.reset(seed=None if seed is None else int(seed) + j, options=options)
            for slot, agent in zip(self._slots(j), self.agents[j]):
                obs[slot] = np.asarray(first[agent], np.float32).reshape(self.obs_dim)
        return obs, {}

    def step(self, actions: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict]:
        """One decision of every car; a race that ends (for any car) is reset in the same step."""
        actions = np.asarray(actions, dtype=np.float32).reshape(self.num_envs, -1)
        n, k = self.num_envs, len(self.objective_names)
        obs = np.zeros((n, self.obs_dim), np.float32)
        rewards = np.zeros((n, k))
        terminated = np.zeros(n, bool)
        truncated = np.zeros(n, bool)
        final_obs = np.empty(n, dtype=object)
        final_info: dict[str, Any] = {}
        for j, race in enumerate(self.races):
            slots, agents = self._slots(j), self.agents[j]
            o, r, term, trunc, info = race.step({a: actions[s] for s, a in zip(slots, agents)})
            for s, a in zip(slots, agents):
                obs[s] = np.asarray(o[a], np.float32).reshape(self.obs_dim)
                rewards[s] = np.asarray(r[a], np.float64).reshape(k)
                terminated[s] = bool(term[a])
                truncated[s] = bool(trunc[a])
            span = slice(slots.start, slots.stop)
            if not (terminated[span].any() or truncated[span].any()):
                continue
            for s, a in zip(slots, agents):  # the race ends for every car: the others are truncated
                truncated[s] = not terminated[s]
                final_obs[s] = obs[s].copy()
                _put(final_info, info[a], s, n)
            first, _ = race.reset()
            for s, a in zip(slots, agents):
                obs[s] = np.asarray(first[a], np.float32).reshape(self.obs_dim)
        done = terminated | truncated
        infos: dict[str, Any] = {}
        if done.any():
            infos = {"final_obs": final_obs, "_final_obs": done.copy(), "final_info": final_info,
                     "_final_info": done.copy()}
        return obs, rewards, terminated, truncated, infos

    def close(self) -> None:
        for race in self.races:
            race.close()


def _put(infos: dict[str, Any], info: dict[str, Any], slot: int, n: int) -> None:
    """Add one slot's info dictionary to gymnasium's vector-info layout (``key`` array + ``_key`` mask)."""
    for key, value in info.items():
        if key not in infos:
            infos[key] = np.empty(n, dtype=object)
            infos["_" + key] = np.zeros(n, bool)
        infos[key][slot] = value
        infos["_" + key][slot] = True
