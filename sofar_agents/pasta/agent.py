"""The PASTA agent: networks, optimiser, normaliser and mu controller wired together.

:class:`PASTA` collects rollouts (:mod:`sofar_agents.pasta.rollout`), updates on them
(targets and attention here, the PPO epochs in :mod:`sofar_agents.pasta.update`),
predicts actions and saves / loads checkpoints (:mod:`sofar_agents.pasta.checkpoint`).
The algorithm is summarised in :mod:`sofar_agents.pasta`.

Randomness: one ``numpy.random.Generator`` and one ``torch.Generator`` owned by the
agent, both derived from ``seed``. The global RNGs are never touched. A checkpoint holds both
generators' states and the collector's rollout state, so that training resumed from it is
bit-identical to training that was not interrupted (:mod:`sofar_agents.pasta.resume`).

:meth:`PASTA.learn` applies each iteration (a rollout and the update on it) as a whole: an
exception or interrupt (Ctrl-C) inside one puts the agent back as it was before it, so that
what is saved afterwards is the last consistent state.
"""

from __future__ import annotations

import copy
import dataclasses
import logging
import time
from collections import deque
from pathlib import Path
from typing import Any, Callable

import numpy as np
import torch

from sofar_agents.pasta.attention import MuController, attention_weights, normalised_regret, update_utopia
from sofar_agents.pasta.buffer import RolloutBuffer
from sofar_agents.pasta.checkpoint import load_agent, save_agent
from sofar_agents.pasta.config import PASTAConfig
from sofar_agents.pasta.distribution import make_squash
from sofar_agents.pasta.gae import compute_gae
from sofar_agents.pasta.networks import Actor, BranchedCritic, network_inputs
from sofar_agents.pasta.rollout import RolloutCollector
from sofar_agents.pasta.running_stats import RunningMeanStd
from sofar_agents.pasta.update import UpdateBatch, ppo_epochs

__all__ = ["PASTA"]

logger = logging.getLogger(__name__)


class PASTA:
    """PASTA agent: collect rollouts, update, predict, save and load.

    Args:
        obs_dim: observation size.
        n_objectives: number of reward objectives K.
        action_low, action_high: bounds of the (box) action, e.g. ``[0.05]``, ``[1.0]``.
        config: hyper-parameters.
        preference: deployment preference w (K non-negative weights, normalised to
            sum 1); default uniform. Training samples per-episode preferences around
            it when ``config.preference_sampling == "dirichlet"``.
        seed: seed of the agent's generators (network init, sampling, minibatches)
            and of the first ``vec_env.reset``.
        objective_names: names of the objectives (stored in checkpoints).
    """

    def __init__(
        self,
        obs_dim: int,
        n_objectives: int,
        action_low: Any,
        action_high: Any,
        config: PASTAConfig | None = None,
        preference: Any = None,
        seed: int = 0,
        objective_names: Any = None,
    ) -> None:
        self.config = config if config is not None else PASTAConfig()
        self.obs_dim = int(obs_dim)
        self.n_objectives = int(n_objectives)
        self.action_low = np.asarray(action_low, dtype=np.float32).reshape(-1)
        self.action_high = np.asarray(action_high, dtype=np.float32).reshape(-1)
        if self.action_low.shape != self.action_high.shape or not np.all(self.action_high > self.action_low):
            raise ValueError(f"invalid action bounds {self.action_low}, {self.action_high}")
        self.act_dim = self.action_low.shape[0]
        self.preference = self._check_preference(preference)
        if self.config.preference_sampling == "trade-off" and (
                self.n_objectives < 2 or self.preference[0] + self.preference[1] <= 0.0):
            raise ValueError("preference_sampling 'trade-off' needs two objectives whose preference weights "
                             f"do not both vanish, got {self.preference.tolist()}")
        names = objective_names if objective_names is not None else [f"objective_{j}" for j in range(n_objectives)]
        self.objective_names = tuple(str(n) for n in names)
        if len(self.objective_names) != self.n_objectives:
            raise ValueError(f"{len(self.objective_names)} objective names for {n_objectives} objectives")
        self.seed = int(seed)

        seq = np.random.SeedSequence(self.seed)
        np_seed, torch_seed = seq.spawn(2)
        self.rng = np.random.default_rng(np_seed)
        self.torch_gen = torch.Generator().manual_seed(int(torch_seed.generate_state(1)[0]))

        cfg = self.config
        in_dim = self.obs_dim + self.n_objectives
        self.actor = Actor(in_dim, self.act_dim, cfg.hidden_sizes, cfg.log_std_init, self.torch_gen)
        self.squash = make_squash(cfg.action_squashing, self.action_low, self.action_high, cfg.squash_margin)
        start = cfg.initial_action
        if start is None and cfg.action_squashing == "clip":
            start = 0.5 * (self.action_low + self.action_high)  # the sigmoid's zero bias: mid-range
        if start is not None:
            frac = (start - self.action_low) / (self.action_high - self.action_low)
            if not np.all((frac > 0.0) & (frac < 1.0)):
                raise ValueError(f"initial_action {cfg.initial_action} must lie strictly inside the action bounds")
            with torch.no_grad():
                self.actor.mean_net[-1].bias.copy_(torch.as_tensor(self.squash.initial_bias(start),
                                                                   dtype=torch.float32))
        self.critic = BranchedCritic(in_dim, self.n_objectives, cfg.hidden_sizes, cfg.critic_head_hidden,
                                     self.torch_gen)
        self.optimizer = torch.optim.Adam(
            [{"params": self.actor.parameters()}, {"params": self.critic.parameters()}],
            lr=cfg.learning_rate,
            eps=cfg.adam_eps,
            fused=True,
        )

        self.return_rms = RunningMeanStd(shape=(self.n_objectives,))
        self.mu_controller = MuController.from_config(cfg)
        self.utopia: np.ndarray | None = None
        self.last_conflict = 0.0
        self.num_timesteps = 0
        self.num_updates = 0
        self.train_time = 0.0
        self.metadata: dict[str, Any] = {}
        self.ep_info_buffer: deque[dict[str, Any]] = deque(maxlen=100)
        self._rollout = RolloutCollector()  # per-env episode state between rollouts (saved as the rollout state)

    # ----------------------------------------------------------------- helpers

    def _check_preference(self, preference: Any) -> np.ndarray:
        if preference is None:
            return np.full(self.n_objectives, 1.0 / self.n_objectives)
        w = np.asarray(preference, dtype=np.float64).reshape(-1)
        if w.shape != (self.n_objectives,) or np.any(w < 0) or not np.isfinite(w).all() or w.sum() <= 0:
            raise ValueError(f"preference must be {self.n_objectives} non-negative weights, got {preference}")
        return w / w.sum()

    def sample_preferences(self, n: int) -> np.ndarray:
        """Preferences of ``n`` new training episodes, ``(n, K)`` float32 (see ``config.preference_sampling``)."""
        if self.config.preference_sampling == "fixed":
            return np.tile(self.preference, (n, 1)).astype(np.float32)
        if self.config.preference_sampling == "trade-off":
            out = np.tile(self.preference, (n, 1))
            share = out[:, 0] + out[:, 1]
            u = self.rng.uniform(0.0, 1.0, size=n)
            out[:, 0], out[:, 1] = u * share, (1.0 - u) * share
            return out.astype(np.float32)
        conc = self.config.dirichlet_concentration * self.n_objectives * np.maximum(self.preference, 1e-3)
        return self.rng.dirichlet(conc, size=n).astype(np.float32)

    def reconfigure(self, **changes: Any) -> None:
        """Change hyper-parameters of an existing agent (e.g. when resuming training).

        The optimiser's learning rate and the mu controller's bounds follow; the
        current mu is kept (clamped to the new bounds). Fields that change the network
        shapes cannot be changed.
        """
        fixed = {"hidden_sizes", "critic_head_hidden", "log_std_init"} & set(changes)
        if fixed:
            raise ValueError(f"cannot change {sorted(fixed)} of an existing agent")
        self.config = dataclasses.replace(self.config, **changes)
        for group in self.optimizer.param_groups:
            group["lr"] = self.config.learning_rate
            group["eps"] = self.config.adam_eps
        mu = self.mu_controller.mu
        self.mu_controller = MuController.from_config(self.config)
        self.mu_controller.mu = min(max(mu, self.config.mu_min), self.config.mu_max)

    def return_scale(self) -> np.ndarray:
        """Per-objective scale dividing the rewards (running std of discounted returns)."""
        if not self.config.normalize_returns:
            return np.ones(self.n_objectives)
        return self.return_rms.std

    # ----------------------------------------------------------------- inference

    def predict(self, obs: Any, deterministic: bool = True, preference: Any = None) -> np.ndarray:
        """Action(s) for ``obs`` of shape ``(obs_dim,)`` or ``(n, obs_dim)``.

        Returns an array of shape ``(act_dim,)`` or ``(n, act_dim)``. The deterministic
        action is the squashed mean. ``preference`` defaults to the agent's preference.
        """
        obs = np.asarray(obs, dtype=np.float32)
        single = obs.ndim == 1
        obs2 = obs.reshape(-1, self.obs_dim)
        w = self.preference if preference is None else self._check_preference(preference)
        x = network_inputs(obs2, np.tile(w, (obs2.shape[0], 1)))
        with torch.inference_mode():
            mean = self.actor(x)
            if deterministic:
                u = mean
            else:
                eps = torch.randn(mean.shape, generator=self.torch_gen)
                u = mean + torch.exp(self.actor.log_std) * eps
            a = self.squash(u).numpy()
        a = np.clip(a, self.action_low, self.action_high)
        return a[0] if single else a

    def log_prob(self, obs: Any, action: Any, preference: Any = None) -> np.ndarray:
        """Log-density of ``action`` (in action units, change of variables included)."""
        obs2 = np.asarray(obs, dtype=np.float32).reshape(-1, self.obs_dim)
        w = self.preference if preference is None else self._check_preference(preference)
        x = network_inputs(obs2, np.tile(w, (obs2.shape[0], 1)))
        a = torch.as_tensor(np.asarray(action, dtype=np.float32).reshape(-1, self.act_dim))
        with torch.inference_mode():
            lp = self.squash.action_log_prob(a, self.actor(x), self.actor.log_std)
        return lp.numpy()

    # ----------------------------------------------------------------- rollout

    def prepare(self, vec_env: Any) -> None:
        """Make ``vec_env`` ready for the next :meth:`collect` now (what the first collect would do first):
        continue the episodes of a loaded checkpoint, or reset the envs with the agent's seed. Lets a caller
        see a failing first reset before it writes anything; the rollouts that follow are the same."""
        self._rollout.prepare(self, vec_env)

    def collect(self, vec_env: Any, n_steps: int | None = None) -> RolloutBuffer:
        """Run the current stochastic policy for ``n_steps`` steps in every env.

        The env is prepared (:meth:`prepare`) on the first call and whenever a
        different vector env is passed; otherwise collection continues from the
        last observation. Updates the return normaliser and ``num_timesteps``. See
        :class:`~sofar_agents.pasta.rollout.RolloutCollector`.
        """
        t_steps = int(n_steps if n_steps is not None else self.config.n_steps)
        buffer = self._rollout.collect(self, vec_env, t_steps)
        self.num_timesteps += t_steps * vec_env.num_envs
        return buffer

    # ----------------------------------------------------------------- update

    def advantages(self, buffer: RolloutBuffer) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Per-objective GAE advantages and lambda-returns of ``buffer`` in normalised units, and the scale.

        The rewards are divided by the current return scale (:meth:`return_scale`) and clipped to
        ``config.reward_clip``. Returns ``(advantages, returns, scale)``, the first two ``(T, N, K)``.
        Changes nothing in the agent.
        """
        cfg = self.config
        scale = self.return_scale()
        rewards = buffer.rewards / scale
        if cfg.reward_clip is not None:
            rewards = np.clip(rewards, -cfg.reward_clip, cfg.reward_clip)
        adv, ret = compute_gae(rewards, buffer.values, buffer.next_values, buffer.terminated, buffer.truncated,
                               cfg.discount, cfg.gae_lambda)
        return adv, ret, scale

    def update(self, buffer: RolloutBuffer) -> dict[str, Any]:
        """One PASTA update (n_epochs of minibatch PPO) on a collected rollout.

        Normalises the rewards by the return scale, computes per-objective GAE
        advantages, updates the utopia and the regrets, moves mu and weights the
        objectives with the attention (see :mod:`sofar_agents.pasta.attention`), then
        runs :func:`~sofar_agents.pasta.update.ppo_epochs`. Returns a dictionary of
        statistics (scalars and per-objective arrays).
        """
        t_start = time.perf_counter()
        cfg = self.config
        k = self.n_objectives
        adv, ret, scale = self.advantages(buffer)

        flat_ret = ret.reshape(-1, k)
        perf = flat_ret.mean(axis=0) * scale  # mean lambda-return, raw units
        best = np.quantile(flat_ret, cfg.utopia_quantile, axis=0) * scale
        self.utopia = update_utopia(self.utopia, best, cfg.utopia_decay)
        regret = normalised_regret(perf, self.utopia, scale, cfg.utopia_margin, cfg.regret_clip)
        if cfg.fixed_mu is not None:
            mu = float(cfg.fixed_mu)
        else:
            mu = self.mu_controller.update(self.num_timesteps, self.last_conflict)

        b = buffer.obs.shape[0] * buffer.obs.shape[1]
        prefs = buffer.preferences.reshape(b, k).astype(np.float64)
        if cfg.scalarization == "linear":
            alpha = prefs
        else:
            alpha = attention_weights(regret[None, :], prefs, mu, cfg.maintenance)

        batch = UpdateBatch(
            inputs=network_inputs(buffer.obs.reshape(b, self.obs_dim), buffer.preferences.reshape(b, k)),
            pre_actions=torch.as_tensor(buffer.pre_actions.reshape(b, self.act_dim)),
            log_probs=torch.as_tensor(buffer.log_probs.reshape(b)),
            advantages=torch.as_tensor(adv.reshape(b, k), dtype=torch.float32),
            returns=torch.as_tensor(ret.reshape(b, k), dtype=torch.float32),
            attention=torch.as_tensor(alpha, dtype=torch.float32),
        )
        log, n_mb, epochs_done = ppo_epochs(self.actor, self.critic, self.optimizer, self.squash, batch, cfg,
                                            self.rng, self.torch_gen)

        if log["conflict"]:
            self.last_conflict = float(np.mean(log["conflict"]))
        self.num_updates += 1
        self.train_time += time.perf_counter() - t_start

        v_pred = buffer.values.reshape(b, k)
        y = ret.reshape(b, k)
        var_y = y.var(axis=0)
        explained = np.where(var_y > 1e-12, 1.0 - (y - v_pred).var(axis=0) / np.maximum(var_y, 1e-12), np.nan)

        def _mean(key: str) -> float:
            return float(np.mean(log[key])) if log[key] else float("nan")

        return {
            "policy_loss": _mean("policy_loss"),
            "value_loss": _mean("value_loss"),
            "entropy": _mean("entropy"),
            "approx_kl": _mean("approx_kl"),
            "clipfrac": _mean("clipfrac"),
            "conflict_ratio": self.last_conflict,
            "mu": mu,
            "epochs": epochs_done,
            "minibatches": n_mb,
            "log_std": float(self.actor.log_std.detach().mean()),
            "attention": alpha.mean(axis=0),
            "regret": regret,
            "utopia": self.utopia.copy() if self.utopia is not None else None,
            "performance": perf,
            "return_scale": scale.copy(),
            "explained_variance": explained,
            "update_time": time.perf_counter() - t_start,
        }

    # ----------------------------------------------------------------- learn

    def learn(
        self,
        vec_env: Any,
        total_steps: int,
        callback: Callable[[PASTA, dict[str, Any]], bool | None] | None = None,
        log_interval: int = 1,
    ) -> PASTA:
        """Alternate :meth:`collect` and :meth:`update` for ``total_steps`` more env steps.

        After every update ``callback(agent, stats)`` is called with the update
        statistics plus ``rollout`` (the :class:`RolloutBuffer`) and ``episodes``; it
        may return ``False`` to stop. A summary is logged at INFO level every
        ``log_interval`` updates.

        Each rollout and its update are applied as a whole: if either raises (or is
        interrupted), the agent (weights, optimiser, normaliser, utopia, mu, counters,
        generators, rollout state) is put back as it was before the rollout and the
        exception propagates; the envs, which moved on, are rebuilt from that rollout
        state by the next :meth:`collect`.
        """
        target = self.num_timesteps + int(total_steps)
        while self.num_timesteps < target:
            before = self._consistent_state()
            try:
                t0 = time.perf_counter()
                buffer = self.collect(vec_env, self.config.n_steps)
                t_collect = time.perf_counter() - t0
                stats = self.update(buffer)
            except BaseException:
                self._restore_consistent_state(before)
                raise
            stats["collect_time"] = t_collect
            stats["sps"] = buffer.rewards.shape[0] * buffer.rewards.shape[1] / (time.perf_counter() - t0)
            stats["rollout"] = buffer
            stats["episodes"] = buffer.episodes
            if log_interval and self.num_updates % log_interval == 0:
                eps = buffer.episodes
                ret = np.mean([e["returns"] for e in eps], axis=0) if eps else None
                logger.info(
                    "update %d  steps %d  episodes %d  mean returns %s  mu %.3f  conflict %.2f  kl %.4f  sps %.0f",
                    self.num_updates, self.num_timesteps, len(eps),
                    np.array2string(ret, precision=3) if ret is not None else "-",
                    stats["mu"], stats["conflict_ratio"], stats["approx_kl"], stats["sps"],
                )
            if callback is not None and callback(self, stats) is False:
                break
        return self

    def _consistent_state(self) -> dict[str, Any]:
        """A copy of everything a rollout and an update change (see :meth:`learn`)."""
        return {
            "actor": copy.deepcopy(self.actor.state_dict()),
            "critic": copy.deepcopy(self.critic.state_dict()),
            "optimizer": copy.deepcopy(self.optimizer.state_dict()),
            "return_rms": (self.return_rms.mean.copy(), self.return_rms.var.copy(), self.return_rms.count),
            "utopia": None if self.utopia is None else self.utopia.copy(),
            "scalars": (self.mu_controller.mu, self.last_conflict, self.num_timesteps, self.num_updates,
                        self.train_time),
            "rng": copy.deepcopy(self.rng.bit_generator.state),
            "torch_gen": self.torch_gen.get_state(),
            "episodes": list(self.ep_info_buffer),
            "rollout": self._rollout.checkpoint_state(),
        }

    def _restore_consistent_state(self, saved: dict[str, Any]) -> None:
        """Put back what :meth:`_consistent_state` copied; the next rollout rebuilds the envs from its rollout state."""
        self.actor.load_state_dict(saved["actor"])
        self.critic.load_state_dict(saved["critic"])
        self.optimizer.load_state_dict(saved["optimizer"])
        self.return_rms.mean, self.return_rms.var, self.return_rms.count = saved["return_rms"]
        self.utopia = saved["utopia"]
        (self.mu_controller.mu, self.last_conflict, self.num_timesteps, self.num_updates,
         self.train_time) = saved["scalars"]
        self.rng.bit_generator.state = saved["rng"]
        self.torch_gen.set_state(saved["torch_gen"])
        self.ep_info_buffer.clear()
        self.ep_info_buffer.extend(saved["episodes"])
        self._rollout.restore(saved["rollout"])

    # ----------------------------------------------------------------- persistence

    def save(self, path: str | Path, metadata: dict[str, Any] | None = None) -> Path:
        """Write ``<stem>.pt`` (tensors only) and ``<stem>.json`` (everything else).

        ``path`` may end in ``.json``, ``.pt`` or have no such suffix. ``metadata``
        (e.g. the training command and env id) is merged into ``self.metadata`` and
        stored under ``"training"``. Returns the JSON path. The format is described in
        :mod:`sofar_agents.pasta.checkpoint`.
        """
        return save_agent(self, path, metadata)

    @classmethod
    def load(cls, path: str | Path) -> PASTA:
        """Load an agent written by :meth:`save` (``torch.load(weights_only=True)``)."""
        return load_agent(cls, path)
