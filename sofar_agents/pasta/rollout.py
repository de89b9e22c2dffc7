"""Rollout collection: run the PASTA policy in a Gymnasium vector env and fill a :class:`RolloutBuffer`.

The vector env must be created with ``autoreset_mode=AutoresetMode.SAME_STEP``, so
that the final observation of an episode is in ``info["final_obs"]`` (needed to
bootstrap truncated episodes). Reward vectors are taken from the environment reward
when it has shape ``(n_envs, K)``, otherwise from ``info["reward_vector"]`` (see
:class:`sofar_agents.wrappers.LinearReward`).

A "vector env" that collects its rollouts itself (it has a ``collect_rollout(agent,
t_steps)`` method, an :class:`sofar_agents.pasta.actor_pool.ActorEnvPool` whose envs live in
worker processes or Ray actors) is handed the whole rollout instead of being stepped here.
:func:`make_training_env` builds the training env of ``train/pasta.py`` (picklable, so
that remote workers can build it).

Between two rollouts the collector holds a :class:`~sofar_agents.pasta.resume.RolloutState`
(``boundary``): what a checkpoint saves so that training resumed from it continues every env's
episode exactly (:mod:`sofar_agents.pasta.resume`). A loaded one is continued by the next rollout.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
import torch

from sofar_agents.pasta.buffer import RolloutBuffer
from sofar_agents.pasta.distribution import gaussian_log_prob
from sofar_agents.pasta.networks import network_inputs
from sofar_agents.pasta.resume import EpisodeRecorder, RolloutState, replay_vector_env, vector_records

if TYPE_CHECKING:
    from sofar_agents.pasta.agent import PASTA

__all__ = ["RolloutCollector", "reward_vectors", "make_training_env", "EPISODE_INFO_KEYS"]

EPISODE_INFO_KEYS = ("is_success", "overtakes", "laps", "collision", "off_track")
"""Final-info entries copied into the episode records of a rollout when present."""

logger = logging.getLogger(__name__)


def _info_item(infos: dict[str, Any], key: str, i: int) -> Any:
    if key not in infos:
        return None
    mask = infos.get("_" + key)
    if mask is not None and not bool(mask[i]):
        return None
    return infos[key][i]


def make_training_env(env_id: str, env_kwargs: dict[str, Any], rho_min: float, rho_max: float,
                      rho_values: Sequence[float] | None = None) -> Any:
    """One PASTA training env: ``env_id`` in vector-reward mode, rho drawn per episode, reward vector in info.

    ``gymnasium.make(env_id, reward_mode="vector", **env_kwargs)`` wrapped in
    :class:`~sofar_agents.wrappers.RandomRhoReset` (rho uniform in ``[rho_min, rho_max]``
    or from ``rho_values``), :class:`~sofar_agents.wrappers.LinearReward` and, outermost,
    :class:`~sofar_agents.pasta.resume.EpisodeRecorder` (for exact resumption). An id
    without ``module:`` that is not registered yet is registered by importing ``sofar_env``.
    A module-level function, so ``functools.partial(make_training_env, ...)`` is a
    picklable env factory.
    """
    import gymnasium as gym

    from sofar_agents.wrappers import LinearReward, RandomRhoReset

    if ":" not in env_id and env_id not in gym.registry:
        import sofar_env  # noqa: F401  (registers the SOfAR ids)
    env = gym.make(env_id, reward_mode="vector", **env_kwargs)
    env = RandomRhoReset(env, rho_min, rho_max, rho_values)
    return EpisodeRecorder(LinearReward(env))


def reward_vectors(rewards: Any, infos: dict[str, Any], done: np.ndarray, n_objectives: int) -> np.ndarray:
    """The ``(n_envs, K)`` reward vectors of one vector-env step.

    The reward itself when it already has that shape (or, for K = 1, shape
    ``(n_envs,)`` without reward-vector infos); otherwise ``info["reward_vector"]``,
    read from ``info["final_info"]`` for the envs whose episode ended (``done``).
    Raises ``ValueError`` when an env provides neither.
    """
    n, k = done.shape[0], n_objectives
    r = np.asarray(rewards, dtype=np.float64)
    if r.shape == (n, k):
        return r
    if k == 1 and r.shape == (n,) and "reward_vector" not in infos and "final_info" not in infos:
        return r[:, None]
    out = np.empty((n, k))
    final = infos.get("final_info", {})
    for i in range(n):
        vec = _info_item(final, "reward_vector", i) if done[i] else None
        if vec is None:
            vec = _info_item(infos, "reward_vector", i)
        if vec is None:
            raise ValueError(
                f"step returned rewards of shape {r.shape} and no info['reward_vector'] for env {i}; "
                f"expected a reward vector of {k} objectives (wrap the env with "
                "sofar_agents.wrappers.LinearReward to use a gymnasium vector env)"
            )
        out[i] = np.asarray(vec, dtype=np.float64).reshape(k)
    return out


class RolloutCollector:
    """Steps a vector env with an agent's stochastic policy and records rollouts.

    Holds, per env, what carries over from one rollout to the next: the last
    observation, the preference of the running episode (drawn with
    :meth:`PASTA.sample_preferences` at every episode start), its discounted and
    undiscounted returns and its length. The env is prepared (:meth:`prepare`) on the
    first rollout and whenever a different vector env is passed: a loaded rollout state
    (:meth:`restore`) is continued, else the env is reset (seeded from the agent's seed
    and update count).
    """

    def __init__(self) -> None:
        self.env: Any = None
        self.last_obs: np.ndarray | None = None
        self.prefs: np.ndarray | None = None
        self.disc_returns: np.ndarray | None = None
        self.ep_returns: np.ndarray | None = None
        self.ep_lengths: np.ndarray | None = None
        self.boundary: RolloutState | None = None
        """The state after the last rollout (or the preparation of the env): what a checkpoint saves."""
        self.pending: RolloutState | None = None
        """A rollout state to continue on the next rollout (:meth:`restore`)."""

    def checkpoint_state(self) -> RolloutState | None:
        """The rollout state a checkpoint saves now: the last boundary, else a restored one not yet continued."""
        return self.boundary if self.boundary is not None else self.pending

    def restore(self, state: RolloutState | None) -> None:
        """Continue ``state`` on the next rollout (None: start fresh episodes); the env is prepared again."""
        self.pending, self.boundary = state, None
        self.env, self.last_obs = None, None

    def prepare(self, agent: PASTA, vec_env: Any) -> None:
        """Make ``vec_env`` ready for the next rollout, unless it already is (it collected the last one).

        A restored rollout state is continued when its episodes can be rebuilt in ``vec_env``
        (:func:`~sofar_agents.pasta.resume.replay_vector_env`, reaching the saved observations); otherwise
        (with a warning) and without one, every env starts a new episode from a seeded :meth:`reset`. Errors
        of the envs (a reset that fails) propagate. Sets :attr:`boundary`.
        """
        if self.env is vec_env and self.boundary is not None:
            return
        pending, self.pending = self.pending, None
        if getattr(vec_env, "collect_rollout", None) is not None:  # an actor pool keeps its per-env state itself
            self.boundary = vec_env.start_rollouts(agent, pending)
            self.env = vec_env
            return
        if pending is None or not self._continue(agent, vec_env, pending):
            self.reset(agent, vec_env)
        self.boundary = self._capture(vec_env)

    def _continue(self, agent: PASTA, vec_env: Any, state: RolloutState) -> bool:
        """Rebuild ``state``'s episodes in ``vec_env``; False (logged) if they cannot be rebuilt exactly."""
        try:
            if state.episodes is None:
                raise ValueError("the checkpoint holds no episode records")
            obs = replay_vector_env(vec_env, state.episodes)
            if not np.array_equal(np.asarray(obs, dtype=np.float32).reshape(state.last_obs.shape), state.last_obs):
                raise ValueError("the replayed episodes reach other observations than the saved ones")
        except Exception as err:  # noqa: BLE001 - any failure to rebuild falls back to fresh episodes
            logger.warning("cannot continue the saved episodes (%s): starting new episodes with a seeded reset, "
                           "so the resumed run is not bit-identical to an uninterrupted one", err)
            return False
        self.env = vec_env
        self.last_obs, self.prefs = state.last_obs.copy(), state.prefs.copy()
        self.disc_returns, self.ep_returns = state.disc_returns.copy(), state.ep_returns.copy()
        self.ep_lengths = state.ep_lengths.copy()
        return True

    def _capture(self, vec_env: Any) -> RolloutState:
        assert self.last_obs is not None and self.prefs is not None and self.disc_returns is not None
        assert self.ep_returns is not None and self.ep_lengths is not None
        return RolloutState(self.last_obs.copy(), self.prefs.copy(), self.disc_returns.copy(),
                            self.ep_returns.copy(), self.ep_lengths.copy(), vector_records(vec_env))

    def reset(self, agent: PASTA, vec_env: Any) -> None:
        """Check the autoreset mode, reset ``vec_env`` and start new episodes in every env."""
        mode = vec_env.metadata.get("autoreset_mode")
        if mode is None or getattr(mode, "value", mode) != "SameStep":
            raise ValueError(
                "PASTA.collect needs a vector env created with "
                "autoreset_mode=gymnasium.vector.AutoresetMode.SAME_STEP "
                f"(got {mode!r}), so that the final observation of truncated episodes "
                "is available for bootstrapping"
            )
        n = vec_env.num_envs
        obs, _ = vec_env.reset(seed=agent.seed + agent.num_updates * 7919)
        self.env = vec_env
        self.last_obs = np.asarray(obs, dtype=np.float32).reshape(n, agent.obs_dim)
        self.prefs = agent.sample_preferences(n)
        self.disc_returns = np.zeros((n, agent.n_objectives))
        self.ep_returns = np.zeros((n, agent.n_objectives))
        self.ep_lengths = np.zeros(n, dtype=np.int64)

    def _switch_preferences(self, agent: PASTA, t: int, next_obs: Any, done: np.ndarray, trunc_b: np.ndarray,
                            final_val: np.ndarray) -> None:
        """Every ``preference_interval`` steps of a running episode: end the segment at step ``t`` as a
        truncation bootstrapped from ``V(next_obs, old preference)``, then draw the env's next preference."""
        assert self.ep_lengths is not None and self.prefs is not None
        due = np.flatnonzero(~done & (self.ep_lengths % agent.config.preference_interval == 0))
        if not due.size:
            return
        obs = np.asarray(next_obs, dtype=np.float32).reshape(done.shape[0], agent.obs_dim)[due]
        with torch.no_grad():
            final_val[t, due] = agent.critic(network_inputs(obs, self.prefs[due])).numpy()
        trunc_b[t, due] = True
        self.prefs[due] = agent.sample_preferences(due.size)

    def collect(self, agent: PASTA, vec_env: Any, t_steps: int) -> RolloutBuffer:
        """Run ``t_steps`` steps in every env of ``vec_env`` with ``agent``'s stochastic policy.

        Updates the agent's return normaliser (``return_rms``) with the running
        discounted returns and appends finished episodes to ``agent.ep_info_buffer``.
        ``next_values`` of the buffer hold V of each transition's true successor:
        zero after termination, ``V(final_obs)`` after truncation.
        """
        self.prepare(agent, vec_env)
        remote = getattr(vec_env, "collect_rollout", None)
        if remote is not None:  # the envs live elsewhere (e.g. Ray actors) and collect the rollout themselves
            if agent.config.preference_interval:
                raise ValueError("preference_interval > 0 is implemented by the local rollout collector only "
                                 "(train/pasta.py --backend local)")
            buffer = remote(agent, t_steps)
            self.boundary = vec_env.rollout_state()
            return buffer
        cfg = agent.config
        assert self.last_obs is not None and self.prefs is not None
        assert self.disc_returns is not None and self.ep_returns is not None and self.ep_lengths is not None
        n, k = vec_env.num_envs, agent.n_objectives
        obs_dim, act_dim = agent.obs_dim, agent.act_dim

        obs_b = np.zeros((t_steps, n, obs_dim), dtype=np.float32)
        pref_b = np.zeros((t_steps, n, k), dtype=np.float32)
        u_b = np.zeros((t_steps, n, act_dim), dtype=np.float32)
        act_b = np.zeros((t_steps, n, act_dim), dtype=np.float32)
        logp_b = np.zeros((t_steps, n), dtype=np.float32)
        rew_b = np.zeros((t_steps, n, k))
        val_b = np.zeros((t_steps, n, k))
        next_val_b = np.zeros((t_steps, n, k))
        final_val = np.zeros((t_steps, n, k))
        term_b = np.zeros((t_steps, n), dtype=bool)
        trunc_b = np.zeros((t_steps, n), dtype=bool)
        episodes: list[dict[str, Any]] = []
        std = torch.exp(agent.actor.log_std.detach())

        for t in range(t_steps):
            x = network_inputs(self.last_obs, self.prefs)
            with torch.no_grad():
                mean = agent.actor(x)
                u = mean + std * torch.randn(mean.shape, generator=agent.torch_gen)
                logp = gaussian_log_prob(u, mean, agent.actor.log_std)
                values = agent.critic(x)
                action = agent.squash(u)
            actions = np.clip(action.numpy(), agent.action_low, agent.action_high)
            next_obs, rewards, terminated, truncated, infos = vec_env.step(actions)
            terminated = np.asarray(terminated, dtype=bool).reshape(n)
            truncated = np.asarray(truncated, dtype=bool).reshape(n)
            done = terminated | truncated
            rvec = reward_vectors(rewards, infos, done, k)

            obs_b[t], pref_b[t], u_b[t], act_b[t] = self.last_obs, self.prefs, u.numpy(), actions
            logp_b[t], rew_b[t], val_b[t] = logp.numpy(), rvec, values.numpy()
            term_b[t], trunc_b[t] = terminated, truncated

            self.disc_returns = self.disc_returns * cfg.discount + rvec
            agent.return_rms.update(self.disc_returns)
            self.ep_returns += rvec
            self.ep_lengths += 1

            boot = np.flatnonzero(truncated & ~terminated)
            if boot.size:
                final_obs = np.stack([np.asarray(infos["final_obs"][i], dtype=np.float32) for i in boot])
                with torch.no_grad():
                    final_val[t, boot] = agent.critic(network_inputs(final_obs, self.prefs[boot])).numpy()

            if done.any():
                final_info = infos.get("final_info", {})
                idx = np.flatnonzero(done)
                for i in idx:
                    ep: dict[str, Any] = {
                        "returns": self.ep_returns[i].copy(),
                        "length": int(self.ep_lengths[i]),
                        "preference": self.prefs[i].copy(),
                    }
                    for key in EPISODE_INFO_KEYS:
                        val = _info_item(final_info, key, i)
                        if val is not None:
                            ep[key] = float(val)
                    episodes.append(ep)
                    agent.ep_info_buffer.append(ep)
                self.disc_returns[idx] = 0.0
                self.ep_returns[idx] = 0.0
                self.ep_lengths[idx] = 0
                self.prefs[idx] = agent.sample_preferences(idx.size)
            if cfg.preference_interval:
                self._switch_preferences(agent, t, next_obs, done, trunc_b, final_val)
            self.last_obs = np.asarray(next_obs, dtype=np.float32).reshape(n, obs_dim)

        with torch.no_grad():
            last_values = agent.critic(network_inputs(self.last_obs, self.prefs)).numpy()
        next_val_b[:-1] = val_b[1:]
        next_val_b[-1] = last_values
        ended = term_b | trunc_b
        next_val_b[ended] = final_val[ended]  # zero for terminated, V(final_obs) for truncated
        self.boundary = self._capture(vec_env)
        return RolloutBuffer(obs_b, pref_b, u_b, act_b, logp_b, rew_b, val_b, next_val_b, term_b, trunc_b,
                             episodes)
