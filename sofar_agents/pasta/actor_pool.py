"""PASTA rollouts in worker actors: each owns a slice of the envs and a copy of the policy, and steps it in chunks.

The envs (and their solvers) live in ``num_workers`` actors, the learner in the driver.
:class:`ActorEnvPool` spreads ``n_envs`` training envs over the actors (contiguous slices;
each actor builds its envs once and keeps them for the whole run). Passed to
:meth:`PASTA.learn` in place of a vector env, it collects each rollout itself (see
:mod:`sofar_agents.pasta.rollout`): the driver sends the actor network's weights once per
rollout and every actor steps its envs with them, with no barrier between the actors at
each step; the driver then computes the values, the return normaliser and the episode
records. Where the actors run is up to a subclass: worker processes on this machine
(:class:`~sofar_agents.pasta.process_rollout.ProcessEnvPool`) or Ray actors
(:class:`~sofar_agents.pasta.ray_rollout.RayEnvPool`).

Same result as a gymnasium vector env. A seeded run gives the same buffers, updates and
checkpoints as ``AsyncVectorEnv`` with the same ``n_envs``: env i is seeded exactly as
the local env i; the exploration noise is drawn in the driver from the agent's torch
generator in the local order and shipped with the weights; an actor evaluates the
policy on a batch of all ``n_envs`` rows with its own at their local positions (other
rows zero), so every float operation has the operands and shapes it has locally. The
one coupling between envs is the preference of a new episode: the local collector draws
it from the agent's generator when the episode ends, jointly for all envs that end at
the same step, in step order. So an actor whose env finished an episode at step t waits
until every other actor has passed step t, then the driver draws the preferences of
that step's episodes exactly as locally. Actors advance in chunks of ``chunk_steps``
steps so that this wait stays short; the chunk size does not change the result.
Bit-identity assumes that the actors run the same torch build on the same kind of CPU as
the driver (float kernels differ between instruction sets) and that the local run used one
torch thread (``--torch-threads 1``, the default), as the actors do.

Between rollouts the pool keeps each env's episode state (as the local collector does) and reports
it, with each env's :class:`~sofar_agents.pasta.resume.EpisodeRecord`, as a
:class:`~sofar_agents.pasta.resume.RolloutState` (:meth:`ActorEnvPool.rollout_state`) for checkpoints;
:meth:`ActorEnvPool.start_rollouts` continues a loaded one by replaying each actor's episodes.

A dead actor ends the run with ``RuntimeError`` (the env state it held is lost); the
agent is left as it was before the rollout, so ``train/pasta.py`` still writes its final
checkpoint and the run can be resumed from it. A rollout that fails (or is interrupted) closes
the pool: the other actors are mid-rollout with calls unanswered.
"""

from __future__ import annotations

import abc
import functools
import itertools
import logging
import warnings
from collections.abc import Callable, Sequence
from typing import Any

import gymnasium as gym
import numpy as np
import torch

from sofar_agents.pasta.buffer import RolloutBuffer
from sofar_agents.pasta.distribution import gaussian_log_prob, make_squash
from sofar_agents.pasta.networks import Actor, network_inputs
from sofar_agents.pasta.resume import EpisodeRecord, RolloutState, replay_vector_env, vector_records
from sofar_agents.pasta.rollout import EPISODE_INFO_KEYS, _info_item, reward_vectors

__all__ = ["ActorEnvPool", "EnvSlice", "slices"]

logger = logging.getLogger(__name__)


def slices(n_envs: int, num_workers: int) -> list[tuple[int, int]]:
    """The contiguous env ranges ``[lo, hi)`` of ``num_workers`` actors over ``n_envs`` envs (as even as possible)."""
    if not 1 <= int(num_workers) <= int(n_envs):
        raise ValueError(f"num_workers must lie in [1, n_envs = {n_envs}], got {num_workers}")
    cuts = [round(w * n_envs / num_workers) for w in range(int(num_workers) + 1)]
    return list(itertools.pairwise(cuts))


def sync_vector_env(env_fns: Sequence[Callable[[], gym.Env]]) -> gym.vector.SyncVectorEnv:
    """The envs of one actor: a gymnasium ``SyncVectorEnv`` with same-step autoreset."""
    return gym.vector.SyncVectorEnv(list(env_fns), autoreset_mode=gym.vector.AutoresetMode.SAME_STEP)


def slice_factories(fns: Sequence[Callable[[], Any]], worker_slices: list[tuple[int, int]],
                    cars_per_race: int | None) -> list[Callable[[], Any]]:
    """Per worker, a picklable factory of its vector env: :func:`sync_vector_env` of its envs, or with
    ``cars_per_race`` a :class:`~sofar_agents.pasta.self_play.RaceVectorEnv` of its races."""
    if cars_per_race is None:
        return [functools.partial(sync_vector_env, list(fns[lo:hi])) for lo, hi in worker_slices]
    from sofar_agents.pasta.self_play import RaceVectorEnv

    return [functools.partial(RaceVectorEnv, list(fns[lo:hi])) for lo, hi in worker_slices]


class EnvSlice:
    """Actor body: slots ``start .. start + m - 1`` of the pool (the envs, or the cars of the races, of one
    vector env) and a copy of the PASTA actor network."""

    def __init__(self, make_vector: Callable[[], Any], start: int, n_total: int) -> None:
        warnings.simplefilter("ignore", UserWarning)  # keep worker output off the driver's console
        torch.set_num_threads(1)
        self.env = make_vector()
        self.start, self.m, self.n_total = int(start), int(self.env.num_envs), int(n_total)
        self.policy: Actor | None = None
        self.obs: np.ndarray | None = None

    def describe(self) -> tuple:
        env = self.env
        return env.single_observation_space, env.single_action_space, dict(env.metadata)

    def get_attr(self, name: str) -> tuple:
        return self.env.get_attr(name)

    def reset(self, seed: int) -> np.ndarray:
        """Reset the vector env with ``seed`` (env, or race, ``i`` of it with ``seed + i``); the observations."""
        obs, _ = self.env.reset(seed=seed)
        self.obs = np.asarray(obs, dtype=np.float32).reshape(self.m, -1)
        return self.obs

    def episode_records(self) -> list[EpisodeRecord] | None:
        """The episode record of each of its envs (None if its envs keep none, e.g. races)."""
        return vector_records(self.env)

    def replay(self, records: list[EpisodeRecord]) -> np.ndarray:
        """Rebuild its envs' episodes from ``records`` (:func:`~sofar_agents.pasta.resume.replay_vector_env`);
        the observations reached."""
        obs = replay_vector_env(self.env, records)
        self.obs = np.asarray(obs, dtype=np.float32).reshape(self.m, -1)
        return self.obs

    def begin(self, state: dict[str, np.ndarray], spec: tuple, noise: np.ndarray, prefs: np.ndarray,
              n_objectives: int, max_steps: int) -> dict[str, Any]:
        """Start a rollout of ``len(noise)`` steps with the actor weights ``state``; run the first chunk."""
        in_dim, act_dim, hidden, log_std_init, low, high, squashing, margin = spec
        if self.policy is None:
            self.policy = Actor(in_dim, act_dim, tuple(hidden), log_std_init, torch.Generator().manual_seed(0))
            self.low, self.high = np.array(low), np.array(high)  # writable copies (Ray hands out read-only arrays)
            self.squash = make_squash(squashing, self.low, self.high, margin)
        self.policy.load_state_dict({k: torch.tensor(v) for k, v in state.items()})
        self.std = torch.exp(self.policy.log_std.detach())
        self.noise, self.prefs, self.k = noise, prefs.copy(), int(n_objectives)
        self.t, self.t_steps = 0, noise.shape[0]
        return self.advance(None, max_steps)

    def advance(self, new_prefs: dict[int, np.ndarray] | None, max_steps: int) -> dict[str, Any]:
        """Run until one of the envs ends an episode, the rollout ends or ``max_steps`` steps are done."""
        assert self.policy is not None and self.obs is not None
        for j, pref in (new_prefs or {}).items():
            self.prefs[j] = pref
        s, e, n = self.start, self.start + self.m, self.n_total
        rows: dict[str, list] = {key: [] for key in ("obs", "u", "actions", "logp", "rewards", "term", "trunc")}
        final_obs: dict[tuple[int, int], np.ndarray] = {}
        ep_info: dict[tuple[int, int], dict[str, float]] = {}
        t0, ended = self.t, np.zeros(0, dtype=np.int64)
        while self.t < self.t_steps and self.t - t0 < max_steps:
            obs_pad = np.zeros((n, self.obs.shape[1]), dtype=np.float32)
            pref_pad = np.zeros((n, self.k), dtype=np.float32)
            noise_pad = np.zeros((n, self.noise.shape[2]), dtype=np.float32)
            obs_pad[s:e], pref_pad[s:e], noise_pad[s:e] = self.obs, self.prefs, self.noise[self.t]
            with torch.no_grad():
                mean = self.policy(network_inputs(obs_pad, pref_pad))
                u = mean + self.std * torch.as_tensor(noise_pad)
                logp = gaussian_log_prob(u, mean, self.policy.log_std)
                action = self.squash(u)
            actions = np.clip(action.numpy(), self.low, self.high)[s:e]
            next_obs, rewards, terminated, truncated, infos = self.env.step(actions)
            terminated = np.asarray(terminated, dtype=bool).reshape(self.m)
            truncated = np.asarray(truncated, dtype=bool).reshape(self.m)
            done = terminated | truncated
            for key, val in (("obs", self.obs), ("u", u.numpy()[s:e]), ("actions", actions),
                             ("logp", logp.numpy()[s:e]), ("rewards", reward_vectors(rewards, infos, done, self.k)),
                             ("term", terminated), ("trunc", truncated)):
                rows[key].append(val)
            final_info = infos.get("final_info", {})
            for j in np.flatnonzero(truncated & ~terminated):
                final_obs[(self.t, s + j)] = np.asarray(infos["final_obs"][j], dtype=np.float32)
            for j in np.flatnonzero(done):
                items = {key: _info_item(final_info, key, j) for key in EPISODE_INFO_KEYS}
                ep_info[(self.t, s + j)] = {key: float(v) for key, v in items.items() if v is not None}
            self.obs = np.asarray(next_obs, dtype=np.float32).reshape(self.m, -1)
            self.t += 1
            if done.any():
                ended = np.flatnonzero(done)
                break
        chunk = {key: np.stack(vals) for key, vals in rows.items()}
        chunk.update(t0=t0, t_end=self.t - 1, ended=ended, final_obs=final_obs, ep_info=ep_info,
                     last_obs=self.obs.copy() if self.t == self.t_steps else None)
        return chunk


class ActorEnvPool(abc.ABC):
    """``n_envs`` training envs in actors, used by :meth:`PASTA.learn` like a vector env (module docstring).

    ``fns`` are picklable factories of the envs, or with ``cars_per_race`` of PettingZoo races of that many cars
    (:func:`~sofar_agents.pasta.self_play.make_self_play_race`; every car is a slot, as in
    :class:`~sofar_agents.pasta.self_play.RaceVectorEnv`). They are split over ``num_workers`` workers in
    contiguous slices. A subclass starts the actors (actor ``w`` an :class:`EnvSlice` of ``_vector_fns[w]``,
    its slots ``slices[w]``) and provides the transport:
    :meth:`_submit` (call a method of actor ``w``, without waiting), :meth:`_wait_any` (the first finished of
    some calls), :meth:`_result` (the value of a finished call, raising the actor's failure), :meth:`_share`
    (an argument sent to every actor) and :meth:`close`. Each actor has at most one call in flight.
    After its constructor it sets ``single_observation_space``, ``single_action_space`` and ``metadata``
    (:meth:`_describe`).
    """

    worker_label = "rollout worker"
    """How an error message names an actor."""

    def __init__(self, fns: Sequence[Callable[[], Any]], num_workers: int, chunk_steps: int,
                 cars_per_race: int | None = None) -> None:
        if chunk_steps < 1:
            raise ValueError(f"chunk_steps must be positive, got {chunk_steps}")
        if cars_per_race is not None and int(cars_per_race) < 1:
            raise ValueError(f"cars_per_race must be positive, got {cars_per_race}")
        units = slices(len(fns), num_workers)  # envs (or races) per worker
        per = 1 if cars_per_race is None else int(cars_per_race)
        self.slices = [(lo * per, hi * per) for lo, hi in units]
        """Per worker, its slots ``[lo, hi)`` (an env each, or a car of a race each)."""
        self.seed_offsets = [lo for lo, _ in units]
        """Per worker, the index of its first env (or race): the offset of its reset seed."""
        self._vector_fns = slice_factories(fns, units, cars_per_race)
        self.num_envs, self.chunk_steps = len(fns) * per, int(chunk_steps)
        self.closed = False
        self._state: dict[str, np.ndarray] | None = None  # per-env episode state between rollouts

    # ----------------------------------------------------------------- transport (subclasses)

    @abc.abstractmethod
    def _submit(self, w: int, method: str, *args: Any) -> Any:
        """Call ``method(*args)`` of actor ``w`` without waiting; a handle of the call."""

    @abc.abstractmethod
    def _wait_any(self, handles: list) -> Any:
        """The first of the calls ``handles`` to finish."""

    @abc.abstractmethod
    def _result(self, w: int, handle: Any) -> Any:
        """The value of actor ``w``'s finished call ``handle``; raises what the call raised."""

    def _share(self, obj: Any) -> Any:
        """``obj`` as an argument of calls to every actor (Ray: one copy in its object store)."""
        return obj

    @abc.abstractmethod
    def close(self) -> None:
        """Stop the actors; sets :attr:`closed`. A second call does nothing."""

    # ----------------------------------------------------------------- common

    def _describe(self) -> None:
        """Spaces and metadata of the envs, from actor 0."""
        obs_space, act_space, metadata = self._get(0, self._call(0, "describe"))
        self.single_observation_space, self.single_action_space = obs_space, act_space
        self.metadata = {**metadata, "autoreset_mode": gym.vector.AutoresetMode.SAME_STEP}

    def _check_open(self) -> None:
        if self.closed:
            raise RuntimeError(f"the {type(self).__name__} is closed")

    def _failure(self, w: int, err: BaseException) -> RuntimeError:
        lo, hi = self.slices[w]
        return RuntimeError(f"{self.worker_label} {w} (envs {lo}..{hi - 1}) failed: {err}")

    def _call(self, w: int, method: str, *args: Any) -> Any:
        """Start actor ``w``'s ``method``; a handle for :meth:`_get`. ``RuntimeError`` naming the worker if it is gone."""
        try:
            return self._submit(w, method, *args)
        except Exception as err:
            raise self._failure(w, err) from err

    def _get(self, w: int, handle: Any) -> Any:
        """The result of actor ``w``'s call; ``RuntimeError`` naming the worker and its envs if it failed."""
        try:
            return self._result(w, handle)
        except Exception as err:
            raise self._failure(w, err) from err

    def _call_all(self, method: str, args: Sequence[tuple] | None = None) -> list[Any]:
        """``method`` of every actor (``args[w]`` for actor ``w``), answers in actor order; the first failure
        is raised once every answer has been read (so that none is left for a later call)."""
        refs = [self._call(w, method, *(args[w] if args is not None else ())) for w in range(len(self.slices))]
        values, error = [], None
        for w, ref in enumerate(refs):
            try:
                values.append(self._get(w, ref))
            except RuntimeError as err:
                error = error or err
        if error is not None:
            raise error
        return values

    def get_attr(self, name: str) -> tuple:
        """Attribute ``name`` of every env (through the wrappers), in env order."""
        self._check_open()
        return tuple(v for values in self._call_all("get_attr", [(name,)] * len(self.slices)) for v in values)

    # ----------------------------------------------------------------- rollout state

    def start_rollouts(self, agent: Any, resume: RolloutState | None) -> RolloutState:
        """Begin the episodes of the next rollouts: continue ``resume`` where each actor can replay its
        episodes to the saved observations, else (logged) and without it start new ones with a seeded reset
        (as :meth:`RolloutCollector.prepare`); the rollout state at that point. A failure closes the pool, as
        a failed rollout does."""
        self._check_open()
        try:
            if resume is None or not self._continue(resume):
                self._state = self._reset(agent)
            return self.rollout_state()
        except BaseException:
            self.close()
            raise

    def _continue(self, st: RolloutState) -> bool:
        try:
            if st.episodes is None:
                raise ValueError("the checkpoint holds no episode records")
            if st.n_envs != self.num_envs:
                raise ValueError(f"the checkpoint holds {st.n_envs} envs, the pool has {self.num_envs}")
            obs = np.concatenate(self._call_all("replay", [(st.episodes[lo:hi],) for lo, hi in self.slices]))
            if not np.array_equal(obs.reshape(st.last_obs.shape), st.last_obs):
                raise ValueError("the replayed episodes reach other observations than the saved ones")
        except (ValueError, RuntimeError) as err:
            logger.warning("cannot continue the saved episodes (%s): starting new episodes with a seeded reset, "
                           "so the resumed run is not bit-identical to an uninterrupted one", err)
            return False
        self._state = {"prefs": st.prefs.copy(), "disc": st.disc_returns.copy(), "ret": st.ep_returns.copy(),
                       "len": st.ep_lengths.copy(), "last_obs": st.last_obs.copy()}
        return True

    def rollout_state(self) -> RolloutState:
        """The per-env state between two rollouts, with every env's episode record (None for races)."""
        self._check_open()
        if self._state is None:
            raise RuntimeError("no rollout has begun yet")
        per_actor = self._call_all("episode_records")
        records = None if any(r is None for r in per_actor) else [r for rs in per_actor for r in rs]
        st = self._state
        return RolloutState(st["last_obs"].copy(), st["prefs"].copy(), st["disc"].copy(), st["ret"].copy(),
                            st["len"].copy(), records)

    # ----------------------------------------------------------------- rollout

    def _reset(self, agent: Any) -> dict[str, np.ndarray]:
        seed = agent.seed + agent.num_updates * 7919  # as RolloutCollector.reset
        obs = self._call_all("reset", [(seed + offset,) for offset in self.seed_offsets])
        n, k = self.num_envs, agent.n_objectives
        return {"prefs": agent.sample_preferences(n), "disc": np.zeros((n, k)), "ret": np.zeros((n, k)),
                "len": np.zeros(n, dtype=np.int64), "last_obs": np.concatenate(obs)}

    def collect_rollout(self, agent: Any, t_steps: int) -> RolloutBuffer:
        """One rollout of ``t_steps`` steps per env, as :meth:`RolloutCollector.collect` would collect it locally."""
        self._check_open()
        rng_state, torch_state = agent.rng.bit_generator.state, agent.torch_gen.get_state()
        try:
            start = self._state if self._state is not None else self._reset(agent)
            chunks, draws = self._run_actors(agent, t_steps, start["prefs"])
        except BaseException:  # leave the agent as it was (its generators advanced during the rollout)
            agent.rng.bit_generator.state = rng_state
            agent.torch_gen.set_state(torch_state)
            self.close()  # the actors' envs are mid-rollout, some calls unanswered: the pool cannot go on
            raise
        self._state = self._assemble(agent, t_steps, start, chunks, draws)
        return self._state.pop("buffer")

    def _run_actors(self, agent: Any, t_steps: int,
                    prefs: np.ndarray) -> tuple[list[list[dict]], dict[int, np.ndarray]]:
        """Step all actors through the rollout; the preference draws of step t happen once every actor passed t."""
        n_w = len(self.slices)
        noise = np.stack([torch.randn((self.num_envs, agent.act_dim), generator=agent.torch_gen).numpy()
                          for _ in range(t_steps)])  # the local collector's per-step draws, in its order
        state = self._share({k: v.detach().numpy() for k, v in agent.actor.state_dict().items()})
        spec = (agent.obs_dim + agent.n_objectives, agent.act_dim, agent.config.hidden_sizes,
                agent.config.log_std_init, agent.action_low, agent.action_high, agent.config.action_squashing,
                agent.config.squash_margin)
        chunks: list[list[dict]] = [[] for _ in range(n_w)]
        known = [-1] * n_w  # last step each actor has reported
        waiting: dict[int, int] = {}  # actor -> step at which one of its envs ended an episode
        in_flight = {self._call(w, "begin", state, spec, noise[:, lo:hi], prefs[lo:hi], agent.n_objectives,
                                  self.chunk_steps): w
                     for w, (lo, hi) in enumerate(self.slices)}
        draws: dict[int, np.ndarray] = {}
        while in_flight or waiting:
            while waiting:
                t_star = min(waiting.values())
                if any(known[w] < t_star for w in range(n_w) if w not in waiting):
                    break
                group = sorted(w for w, t in waiting.items() if t == t_star)
                idx = np.concatenate([self.slices[w][0] + chunks[w][-1]["ended"] for w in group])
                draws[t_star] = agent.sample_preferences(idx.size)  # as the local collector at step t_star
                for w in group:
                    del waiting[w]
                    if t_star < t_steps - 1:
                        lo = self.slices[w][0]
                        new = {int(i - lo): p for i, p in zip(idx, draws[t_star]) if lo <= i < self.slices[w][1]}
                        in_flight[self._call(w, "advance", new, self.chunk_steps)] = w
            if not in_flight:
                break
            ready = self._wait_any(list(in_flight))
            w = in_flight.pop(ready)
            chunk = self._get(w, ready)
            chunks[w].append(chunk)
            known[w] = chunk["t_end"]
            if chunk["ended"].size:
                waiting[w] = chunk["t_end"]
            elif chunk["last_obs"] is None:
                in_flight[self._call(w, "advance", None, self.chunk_steps)] = w
        return chunks, draws

    def _assemble(self, agent: Any, t_steps: int, start: dict[str, np.ndarray], chunks: list[list[dict]],
                  draws: dict[int, np.ndarray]) -> dict[str, Any]:
        """The rollout buffer (``"buffer"``) and the per-env episode state after it, computed as locally.

        Updates the agent's return normaliser and episode records as the local collector does.
        """
        st: dict[str, Any] = {key: v.copy() for key, v in start.items()}
        n, k, cfg = self.num_envs, agent.n_objectives, agent.config
        full = {key: np.concatenate([np.concatenate([c[key] for c in cs]) for cs in chunks], axis=1)
                for key in ("obs", "u", "actions", "logp", "rewards", "term", "trunc")}
        final_obs = {key: v for cs in chunks for c in cs for key, v in c["final_obs"].items()}
        ep_info = {key: v for cs in chunks for c in cs for key, v in c["ep_info"].items()}
        last_obs = np.concatenate([cs[-1]["last_obs"] for cs in chunks])
        term, trunc = full["term"], full["trunc"]
        pref_b = np.zeros((t_steps, n, k), dtype=np.float32)
        val_b, final_val = np.zeros((t_steps, n, k)), np.zeros((t_steps, n, k))
        episodes: list[dict[str, Any]] = []
        for t in range(t_steps):
            pref_b[t] = st["prefs"]
            rvec = full["rewards"][t]
            with torch.no_grad():
                val_b[t] = agent.critic(network_inputs(full["obs"][t], st["prefs"])).numpy()
            st["disc"] = st["disc"] * cfg.discount + rvec
            agent.return_rms.update(st["disc"])
            st["ret"] += rvec
            st["len"] += 1
            boot = np.flatnonzero(trunc[t] & ~term[t])
            if boot.size:
                fo = np.stack([final_obs[(t, int(i))] for i in boot])
                with torch.no_grad():
                    final_val[t, boot] = agent.critic(network_inputs(fo, st["prefs"][boot])).numpy()
            idx = np.flatnonzero(term[t] | trunc[t])
            for i in idx:
                ep = {"returns": st["ret"][i].copy(), "length": int(st["len"][i]), "preference": st["prefs"][i].copy(),
                      **ep_info[(t, int(i))]}
                episodes.append(ep)
                agent.ep_info_buffer.append(ep)
            if idx.size:
                st["disc"][idx], st["ret"][idx], st["len"][idx] = 0.0, 0.0, 0
                st["prefs"][idx] = draws[t]
        with torch.no_grad():
            last_values = agent.critic(network_inputs(last_obs, st["prefs"])).numpy()
        next_val = np.zeros((t_steps, n, k))
        next_val[:-1] = val_b[1:]
        next_val[-1] = last_values
        ended = term | trunc
        next_val[ended] = final_val[ended]
        st["last_obs"] = last_obs
        st["buffer"] = RolloutBuffer(full["obs"], pref_b, full["u"], full["actions"], full["logp"], full["rewards"],
                                     val_b, next_val, term, trunc, episodes)
        return st

