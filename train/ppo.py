"""Train the standard-PPO baseline (Stable-Baselines3) on the scalarised SOfAR reward.

Usage (from the repository root, with the package installed)::

    python train/ppo.py                                   # Laguna Seca, defaults
    python train/ppo.py --n-envs 2 --total-steps 800000 --out runs/ppo_ls
    tensorboard --logdir runs

The environment is made with ``mo_gymnasium.make`` and returns its reward vector;
MO-Gymnasium's ``LinearReward`` scalarises it with ``--weights`` (default: the reference deployment preference
0.31 0.45 0.05 0.04 0.15 over safety, overtakes, progress, barrier_margin,
gamma_smoothness), and :class:`sofar_agents.wrappers.RescaleGammaAction` maps the
policy's ``[-1, 1]`` output onto gamma in ``[0.05, 1]``. rho is drawn per episode as in
``train/pasta.py``. The network matches PASTA's (2 x 256, tanh). Outputs in ``--out``:
``tb/``, ``checkpoints/ppo_<steps>_steps.zip`` and ``ppo_final.zip`` (load it for
deployment with :class:`sofar_agents.policies.SB3Policy`).
"""

from __future__ import annotations

import argparse
import json
import logging
from pathlib import Path
from typing import Any

import gymnasium as gym
import mo_gymnasium
import numpy as np
import torch
from mo_gymnasium.wrappers import LinearReward
from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import CheckpointCallback
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv, VecEnv, VecNormalize

from sofar_agents.wrappers import RandomRhoReset, RescaleGammaAction

logger = logging.getLogger("train.ppo")

REFERENCE_PREFERENCE = (0.31, 0.45, 0.05, 0.04, 0.15)
"""Reference deployment preference over the five SOfAR objectives."""
EPISODE_INFO = ("is_success", "overtakes", "laps", "collision", "off_track")


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    p.add_argument("--env-id", default="SOfAR-LagunaSeca-v0", help="Gymnasium id of the training environment")
    p.add_argument("--env-kwargs", default="{}", help="extra gymnasium.make keyword arguments (JSON object)")
    p.add_argument("--decision-interval", type=int, default=None, help="env decision_interval, if set")
    p.add_argument("--weights", type=float, nargs="+", default=None,
                   help="scalarisation weights (default: reference preference for 5 objectives, else ones)")
    p.add_argument("--total-steps", type=int, default=1_000_000, help="environment steps over all envs")
    p.add_argument("--n-envs", type=int, default=1, help="parallel envs (subprocesses when > 1)")
    p.add_argument("--n-steps", type=int, default=2048, help="rollout length per env")
    p.add_argument("--batch-size", type=int, default=64, help="minibatch size")
    p.add_argument("--n-epochs", type=int, default=10, help="epochs per update")
    p.add_argument("--learning-rate", type=float, default=3e-4, help="Adam learning rate")
    p.add_argument("--discount", type=float, default=0.99, help="discount factor")
    p.add_argument("--gae-lambda", type=float, default=0.95, help="GAE lambda")
    p.add_argument("--clip-range", type=float, default=0.2, help="PPO clip range")
    p.add_argument("--ent-coef", type=float, default=0.01, help="entropy coefficient")
    p.add_argument("--vf-coef", type=float, default=0.5, help="value loss coefficient")
    p.add_argument("--max-grad-norm", type=float, default=0.5, help="gradient-norm clip")
    p.add_argument("--hidden-sizes", type=int, nargs="+", default=[256, 256], help="hidden widths (tanh)")
    p.add_argument("--normalize-reward", action=argparse.BooleanOptionalAction, default=True,
                   help="scale rewards by a running std of the discounted return (VecNormalize)")
    p.add_argument("--rho-min", type=float, default=0.1, help="lower bound of the per-episode rho")
    p.add_argument("--rho-max", type=float, default=0.8, help="upper bound of the per-episode rho")
    p.add_argument("--rho-values", type=float, nargs="+", default=None, help="draw rho from these values instead")
    p.add_argument("--seed", type=int, default=1, help="seed")
    p.add_argument("--out", default="runs/ppo", help="output directory")
    p.add_argument("--save-every", type=int, default=100_000, help="checkpoint every this many steps (0: off)")
    p.add_argument("--torch-threads", type=int, default=1, help="torch intra-op threads")
    p.add_argument("--log-level", default="INFO", help="Python logging level")
    return p.parse_args(argv)


def _ensure_registered(env_id: str) -> None:
    if ":" in env_id or env_id in gym.registry:
        return
    import sofar_env  # noqa: F401  (registers the SOfAR ids)

    if env_id not in gym.registry:
        from sofar_env.registration import register_envs

        register_envs()


def make_env(args: argparse.Namespace, env_kwargs: dict[str, Any]) -> Any:
    def thunk() -> gym.Env:
        _ensure_registered(args.env_id)
        env = mo_gymnasium.make(args.env_id, reward_mode="vector", **env_kwargs)
        env = RandomRhoReset(env, args.rho_min, args.rho_max, args.rho_values)
        k = int(env.unwrapped.reward_space.shape[0])
        weights = args.weights
        if weights is None:
            weights = REFERENCE_PREFERENCE if k == len(REFERENCE_PREFERENCE) else [1.0] * k
        if len(weights) != k:
            raise ValueError(f"{len(weights)} weights for a reward space of {k} objectives")
        env = LinearReward(env, weight=np.asarray(weights, dtype=np.float64))
        env = RescaleGammaAction(env)
        return Monitor(env, info_keywords=tuple(k_ for k_ in EPISODE_INFO if k_ != "is_success"))

    return thunk


def main(argv: list[str] | None = None) -> Path:
    args = parse_args(argv)
    logging.basicConfig(level=getattr(logging, args.log_level.upper()), format="%(asctime)s %(name)s: %(message)s")
    torch.set_num_threads(args.torch_threads)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    env_kwargs = json.loads(args.env_kwargs)
    if args.decision_interval is not None:
        env_kwargs["decision_interval"] = args.decision_interval
    _ensure_registered(args.env_id)

    fns = [make_env(args, env_kwargs) for _ in range(args.n_envs)]
    venv: VecEnv = SubprocVecEnv(fns) if args.n_envs > 1 else DummyVecEnv(fns)
    venv.seed(args.seed)
    if args.normalize_reward:
        venv = VecNormalize(venv, norm_obs=False, norm_reward=True, gamma=args.discount)

    model = PPO(
        "MlpPolicy", venv,
        learning_rate=args.learning_rate, n_steps=args.n_steps, batch_size=args.batch_size,
        n_epochs=args.n_epochs, gamma=args.discount, gae_lambda=args.gae_lambda, clip_range=args.clip_range,
        ent_coef=args.ent_coef, vf_coef=args.vf_coef, max_grad_norm=args.max_grad_norm,
        policy_kwargs={"net_arch": list(args.hidden_sizes), "activation_fn": torch.nn.Tanh},
        tensorboard_log=str(out / "tb"), seed=args.seed, device="cpu", verbose=0,
    )
    callbacks = []
    if args.save_every:
        callbacks.append(CheckpointCallback(max(args.save_every // args.n_envs, 1), str(out / "checkpoints"),
                                            name_prefix="ppo", save_vecnormalize=args.normalize_reward))
    model.learn(args.total_steps, callback=callbacks, tb_log_name="ppo", progress_bar=False)
    final = out / "ppo_final.zip"
    model.save(final)
    if args.normalize_reward:
        venv.save(str(out / "ppo_final_vecnormalize.pkl"))
    venv.close()
    logger.info("saved %s after %d steps", final, model.num_timesteps)
    return final


if __name__ == "__main__":
    main()
