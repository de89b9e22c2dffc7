"""Exact continuation of PASTA training: the rollout state a checkpoint holds besides the weights.

A run resumed from a checkpoint continues where the run that wrote it stood after its last update:
every random stream and every environment's running episode, so that it is bit-identical to the run
that was not interrupted (on the same machine, with the same vector env). What that takes:

* the agent's generators: the numpy ``Generator``'s ``bit_generator.state`` (JSON ``state.rng``) and the
  torch ``Generator``'s state (tensor ``torch_generator``), written by the checkpoint module;
* the collector's per-env carry-over, a :class:`RolloutState`: the last observation, the preference of
  the running episode, its discounted and undiscounted returns and its length (tensors under
  ``rollout``; JSON ``rollout.n_envs``);
* per env, an :class:`EpisodeRecord` of how its running episode began (the reset seed, or the states of
  the generators held by the env and its wrappers just before an automatic reset, and the reset
  options) and the actions taken since (JSON ``rollout.episodes``, tensors ``rollout.actions``), kept by
  :class:`EpisodeRecorder`, the outermost wrapper of the training env
  (:func:`~sofar_agents.pasta.rollout.make_training_env`).

On resume every env replays its episode (:meth:`EpisodeRecorder.replay`): it restores the generator
states, resets and steps the recorded actions; the observations reached must equal the saved ones bit
for bit. This assumes an env that is deterministic given its generators and actions, whose randomness
comes from generators held as attributes of the env or one of its wrappers (the SOfAR envs: ``np_random``,
from which each reset derives the rest; :class:`~sofar_agents.wrappers.RandomRhoReset`: its rho
generator) and which carries nothing else over a reset. When the envs cannot be rebuilt (other envs or
another number of them, envs without the recorder such as the self-play races, a replay that does not
reach the saved observations), the collector logs a warning and starts fresh episodes with a seeded reset,
as for a checkpoint without a rollout state: the run goes on, but not bit-identically.
"""

from __future__ import annotations

import copy
import json
import logging
from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np

from sofar_agents.pasta.checkpoint_meta import check_generator_state, is_int

__all__ = ["EpisodeRecord", "RolloutState", "EpisodeRecorder", "generator_states", "set_generator_states",
           "vector_records", "replay_vector_env", "RECORDS_FLAG"]

logger = logging.getLogger(__name__)

RECORDS_FLAG = "pasta_episode_records"
"""Key of the env metadata that :class:`EpisodeRecorder` sets: the envs keep :class:`EpisodeRecord` s."""


@dataclass
class EpisodeRecord:
    """How one env's running episode began and the actions taken since (enough to rebuild it)."""

    seed: int | None
    """The seed of the reset that began it; None for a reset without a seed (an automatic reset)."""
    generators: dict[str, dict] | None
    """For a reset without a seed: ``"<depth>.<attribute>"`` -> ``bit_generator.state`` of every numpy
    ``Generator`` held by the env and its wrappers just before it (depth 0: the outermost below the recorder)."""
    options: dict | None
    """The reset options (JSON values)."""
    actions: np.ndarray
    """The actions taken since, ``(steps, *action_shape)``."""

    def to_json(self) -> dict[str, Any]:
        return {"seed": self.seed, "generators": self.generators, "options": self.options}


@dataclass
class RolloutState:
    """The collector's per-env state between two rollouts (n envs, K objectives)."""

    last_obs: np.ndarray
    """Observation each env will act on next, ``(n, obs_dim)`` float32."""
    prefs: np.ndarray
    """Preference of each env's running episode, ``(n, K)`` float32."""
    disc_returns: np.ndarray
    """Running discounted return vectors (of the return normaliser), ``(n, K)`` float64."""
    ep_returns: np.ndarray
    """Undiscounted return vectors of the running episodes, ``(n, K)`` float64."""
    ep_lengths: np.ndarray
    """Steps of the running episodes, ``(n,)`` int64."""
    episodes: list[EpisodeRecord] | None
    """How to rebuild each env's running episode; None where the envs keep no records."""

    @property
    def n_envs(self) -> int:
        return int(self.last_obs.shape[0])

    # ----------------------------------------------------------------- checkpoint

    def to_checkpoint(self) -> tuple[dict[str, Any], dict[str, Any]]:
        """``(json part, tensor part)`` of the checkpoint's ``rollout`` entries."""
        import torch

        def tensor(arr: np.ndarray) -> Any:
            return torch.from_numpy(np.array(arr, copy=True, order="C"))  # a writable copy (Ray's are read-only)

        tensors: dict[str, Any] = {name: tensor(getattr(self, name))
                                   for name in ("last_obs", "prefs", "disc_returns", "ep_returns", "ep_lengths")}
        if self.episodes is not None:
            tensors["actions"] = [tensor(r.actions) for r in self.episodes]
        meta = {"n_envs": self.n_envs,
                "episodes": None if self.episodes is None else [r.to_json() for r in self.episodes]}
        return meta, tensors

    @classmethod
    def from_checkpoint(cls, meta: Any, tensors: Any, where: str, dims: tuple[int, int]) -> RolloutState:
        """Rebuild from the checkpoint's ``rollout`` entries, checking every one; ``ValueError`` starting with
        ``where`` (the files) and naming the field otherwise. ``dims``: ``(obs_dim, n_objectives)``."""
        check_rollout_meta(meta, where)
        n, (obs_dim, k) = meta["n_envs"], dims
        if not isinstance(tensors, dict):
            raise ValueError(f"{where}: tensor rollout must be a dict of tensors")
        shapes = {"last_obs": ((n, obs_dim), "float32"), "prefs": ((n, k), "float32"),
                  "disc_returns": ((n, k), "float64"), "ep_returns": ((n, k), "float64"),
                  "ep_lengths": ((n,), "int64")}
        arrays = {}
        for name, (shape, dtype) in shapes.items():
            arrays[name] = _array(tensors.get(name), f"{where}: tensor rollout.{name}", shape, dtype)
        if np.any(arrays["ep_lengths"] < 0):
            raise ValueError(f"{where}: tensor rollout.ep_lengths must be >= 0")
        episodes = None
        if meta["episodes"] is not None:
            actions = tensors.get("actions")
            if not isinstance(actions, list) or len(actions) != n:
                raise ValueError(f"{where}: tensor rollout.actions must be a list of {n} tensors")
            episodes = []
            for i, (rec, act) in enumerate(zip(meta["episodes"], actions)):
                arr = _array(act, f"{where}: tensor rollout.actions.{i}", None, None)
                if arr.ndim < 1 or arr.shape[0] != arrays["ep_lengths"][i]:
                    raise ValueError(f"{where}: tensor rollout.actions.{i} holds {arr.shape[:1]} actions for an "
                                     f"episode of {int(arrays['ep_lengths'][i])} steps")
                episodes.append(EpisodeRecord(rec["seed"], rec["generators"], rec["options"], arr))
        return cls(**arrays, episodes=episodes)


def _array(value: Any, where: str, shape: tuple | None, dtype: str | None) -> np.ndarray:
    import torch

    if not isinstance(value, torch.Tensor):
        raise ValueError(f"{where} is missing or not a tensor")
    arr = value.detach().cpu().numpy()
    if shape is not None and (arr.shape != shape or str(arr.dtype) != dtype):
        raise ValueError(f"{where} must be {dtype} of shape {shape}, got {arr.dtype} of shape {arr.shape}")
    return arr.copy()


def check_rollout_meta(meta: Any, where: str) -> None:
    """Check the JSON ``rollout`` entry; ``ValueError`` starting with ``where`` and naming the field."""
    if not isinstance(meta, dict):
        raise ValueError(f"{where}: rollout must be a JSON object, got {meta!r}")
    n = meta.get("n_envs")
    if not (is_int(n) and n >= 1):
        raise ValueError(f"{where}: rollout.n_envs must be a positive integer, got {n!r}")
    episodes = meta.get("episodes")
    if episodes is None:
        return
    if not (isinstance(episodes, list) and len(episodes) == n):
        raise ValueError(f"{where}: rollout.episodes must be null or a list of {n} records, got {episodes!r}")
    for i, rec in enumerate(episodes):
        field = f"rollout.episodes.{i}"
        if not (isinstance(rec, dict) and set(rec) == {"seed", "generators", "options"}):
            raise ValueError(f"{where}: {field} must hold seed, generators and options, got {rec!r}")
        seed, gens = rec["seed"], rec["generators"]
        if (seed is None) == (gens is None):
            raise ValueError(f"{where}: {field} needs either a seed or generators, got {rec!r}")
        if seed is not None and not (is_int(seed) and seed >= 0):
            raise ValueError(f"{where}: {field}.seed must be an integer >= 0, got {seed!r}")
        if gens is not None:
            if not isinstance(gens, dict):
                raise ValueError(f"{where}: {field}.generators must be a JSON object, got {gens!r}")
            for key, state in gens.items():
                depth, _, name = key.partition(".")
                if not (depth.isdigit() and name):
                    raise ValueError(f"{where}: {field}.generators key {key!r} is not '<depth>.<attribute>'")
                check_generator_state(state, f"{where}: {field}.generators.{key}")
        if rec["options"] is not None and not isinstance(rec["options"], dict):
            raise ValueError(f"{where}: {field}.options must be null or a JSON object, got {rec['options']!r}")


# ---------------------------------------------------------------------------- the env side


def _levels(env: Any) -> list[Any]:
    """``env`` and every env it wraps, outermost first."""
    out = [env]
    while isinstance(out[-1], gym.Wrapper):
        out.append(out[-1].env)
    return out


def _json_ready(state: dict) -> dict | None:
    """``state`` if it survives a JSON round trip unchanged, else None."""
    try:
        return state if json.loads(json.dumps(state)) == state else None
    except (TypeError, ValueError):
        return None


def generator_states(env: Any) -> dict[str, dict] | None:
    """``"<depth>.<attribute>"`` -> ``bit_generator.state`` of every numpy ``Generator`` held as an attribute
    by ``env`` or an env it wraps; None if one of them has a state that JSON cannot hold."""
    out: dict[str, dict] = {}
    for depth, level in enumerate(_levels(env)):
        for name, value in vars(level).items():
            if isinstance(value, np.random.Generator):
                state = _json_ready(value.bit_generator.state)
                if state is None:
                    return None
                out[f"{depth}.{name}"] = state
    return out


def set_generator_states(env: Any, states: dict[str, dict]) -> None:
    """Put ``states`` (from :func:`generator_states` of an env built the same way) into ``env``'s generators,
    in place (a generator shared with other objects stays shared); one not there yet is created."""
    levels = _levels(env)
    for key, state in states.items():
        depth, name = key.split(".", 1)
        if int(depth) >= len(levels):
            raise ValueError(f"the env has no wrapper level {depth} for the generator {key!r}")
        level, gen = levels[int(depth)], getattr(levels[int(depth)], name, None)
        if not isinstance(gen, np.random.Generator):
            gen = np.random.Generator(getattr(np.random, state["bit_generator"])())
            setattr(level, name, gen)
        gen.bit_generator.state = state


class EpisodeRecorder(gym.Wrapper):
    """Keeps the :class:`EpisodeRecord` of the running episode (module docstring); changes nothing else.

    Its metadata carries ``RECORDS_FLAG``, so a vector env of recorded envs says so. A vector env sets
    :attr:`pending_replay` (one record per env, ``set_attr``) and calls :meth:`replay_pending` to rebuild.
    """

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        self.metadata = {**env.metadata, RECORDS_FLAG: True}
        self._record: EpisodeRecord | None = None
        self._actions: list[np.ndarray] = []
        self.pending_replay: EpisodeRecord | None = None

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict]:
        generators = generator_states(self.env) if seed is None else None
        opts = _json_ready(options) if isinstance(options, dict) else None
        result = self.env.reset(seed=seed, options=options)
        unrecordable = (seed is None and generators is None) or (options is not None and opts is None)
        self._record = None if unrecordable else EpisodeRecord(None if seed is None else int(seed), generators,
                                                               copy.deepcopy(opts), np.zeros(0))
        self._actions = []
        return result

    def step(self, action: Any) -> tuple[Any, Any, bool, bool, dict]:
        self._actions.append(np.array(action, copy=True))
        return self.env.step(action)

    def episode_record(self) -> EpisodeRecord | None:
        """The running episode's record (None before the first reset or if it cannot be recorded)."""
        if self._record is None:
            return None
        if self._actions:
            actions = np.stack(self._actions)
        else:
            actions = np.zeros((0, *(self.action_space.shape or ())), self.action_space.dtype or np.float32)
        return EpisodeRecord(self._record.seed, copy.deepcopy(self._record.generators),
                             copy.deepcopy(self._record.options), actions)

    def replay(self, record: EpisodeRecord) -> Any:
        """Rebuild the episode of ``record``; its last observation. ``RuntimeError`` if it ends on the way."""
        if record.seed is None:
            self.env.reset(seed=0)  # builds everything a first reset builds; the generators are then replaced
            set_generator_states(self.env, record.generators or {})
        obs, _ = self.reset(seed=record.seed, options=copy.deepcopy(record.options))
        for t, action in enumerate(record.actions):
            obs, _, terminated, truncated, _ = self.step(action)
            if terminated or truncated:  # the recorded actions all kept the episode running
                raise RuntimeError(f"the replayed episode ended at step {t + 1} of {len(record.actions)}")
        return obs

    def replay_pending(self) -> Any:
        """:meth:`replay` the record set in :attr:`pending_replay` (then cleared)."""
        record, self.pending_replay = self.pending_replay, None
        if record is None:
            raise RuntimeError("no episode record to replay")
        return self.replay(record)


def vector_records(vec_env: Any) -> list[EpisodeRecord] | None:
    """The :class:`EpisodeRecord` of every env of a gymnasium vector env of :class:`EpisodeRecorder` envs
    (None for other vector envs or when an env has none)."""
    if not vec_env.metadata.get(RECORDS_FLAG):
        return None
    records = list(vec_env.call("episode_record"))
    return None if any(r is None for r in records) else records


def replay_vector_env(vec_env: Any, records: list[EpisodeRecord]) -> np.ndarray:
    """Rebuild every env's episode from ``records`` (one per env); the observations reached, ``(n, ...)``."""
    if not vec_env.metadata.get(RECORDS_FLAG):
        raise ValueError("its envs keep no episode records (they are not wrapped in EpisodeRecorder)")
    if len(records) != vec_env.num_envs:
        raise ValueError(f"the checkpoint holds {len(records)} envs, the vector env has {vec_env.num_envs}")
    vec_env.set_attr("pending_replay", list(records))
    return np.stack([np.asarray(o) for o in vec_env.call("replay_pending")])
