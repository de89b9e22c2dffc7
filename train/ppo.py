"""Train the standard-PPO baseline (Stable-Baselines3) on the scalarised SOfAR reward.

Usage (from the repository root, with the package installed)::

    python train/ppo.py                                   # Laguna Seca, defaults
    python train/ppo.py --n-envs 2 --total-steps 800000 --out runs/ppo_ls
    python train/ppo.py --resume runs/ppo_ls/ppo_final.zip --total-steps 1200000   # continue in place
    tensorboard --logdir runs

The environment is made with ``mo_gymnasium.make`` and returns its reward vector;
MO-Gymnasium's ``LinearReward`` scalarises it with ``--weights`` (default: the reference deployment preference
0.31 0.45 0.05 0.04 0.15 over safety, overtakes, progress, barrier_margin,
gamma_smoothness), and :class:`sofar_agents.wrappers.RescaleGammaAction` maps the
policy's ``[-1, 1]`` output onto gamma in ``[0.05, 1]``. rho is drawn per episode as in
``train/pasta.py``. The network matches PASTA's (2 x 256, tanh). Outputs in ``--out``:
``tb/``, ``checkpoints/ppo_<steps>_steps.zip`` and ``ppo_final.zip`` (load it for
deployment with :class:`sofar_agents.policies.SB3Policy`). ``--resume`` continues a run in its own
folder (the default ``--out`` with ``--resume``); another ``--out`` that already holds a
``ppo_final.zip`` is refused unless ``--force`` is given, which starts over there.

``--resume PATH.zip`` continues a run: ``PPO.load`` restores the policy, the optimiser and
the hyper-parameters stored in the checkpoint (the PPO options on the command line are
ignored then), the reward normaliser statistics are restored from the matching
``*vecnormalize*.pkl`` written next to it, and training continues up to
``--total-steps`` (counted from the start of the first run). The rollout in progress and
the envs' episode states are not part of a checkpoint, so a resumed run is not
bit-identical to an uninterrupted one.
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
from stable_baselines3.common.callbacks import BaseCallback, CheckpointCallback
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv, VecEnv, VecNormalize

from tqdm import tqdm

from sofar_agents.cli_types import finite_float, float_in, nonneg_float, nonneg_int, positive_float, positive_int
from sofar_agents.wrappers import RandomRhoReset, RescaleGammaAction
from sofar_env.compile import warm_up, world_of
from sofar_env.configs.objectives import REFERENCE_PREFERENCE  # the objectives' registry
from sofar_env.vector import pinned_factories

logger = logging.getLogger("train.ppo")

EPISODE_INFO = ("is_success", "overtakes", "laps", "collision", "off_track")


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    p.add_argument("--env-id", default="SOfAR-LagunaSeca-v0", help="Gymnasium id of the training environment")
    p.add_argument("--env-kwargs", default="{}", help="extra gymnasium.make keyword arguments (JSON object)")
    p.add_argument("--decision-interval", type=positive_int, default=None, help="env decision_interval, if set")
    p.add_argument("--weights", type=finite_float, nargs="+", default=None,
                   help="scalarisation weights (default: reference preference for 5 objectives, else ones)")
    p.add_argument("--total-steps", type=positive_int, default=1_000_000, help="environment steps over all envs")
    p.add_argument("--n-envs", type=positive_int, default=1, help="parallel envs (subprocesses when > 1)")
    p.add_argument("--pin-workers", action=argparse.BooleanOptionalAction, default=True,
                   help="pin each env subprocess to a CPU of its own (Linux, when there are at least as many CPUs "
                        "as envs; sofar_env.vector): same results, fewer stalls between lock-steps")
    p.add_argument("--n-steps", type=positive_int, default=2048, help="rollout length per env")
    p.add_argument("--batch-size", type=positive_int, default=64, help="minibatch size")
    p.add_argument("--n-epochs", type=positive_int, default=10, help="epochs per update")
    p.add_argument("--learning-rate", type=positive_float, default=3e-4, help="Adam learning rate")
    p.add_argument("--discount", type=float_in(0.0, 1.0, low_open=True), default=0.99, help="discount factor")
    p.add_argument("--gae-lambda", type=float_in(0.0, 1.0), default=0.95, help="GAE lambda")
    p.add_argument("--clip-range", type=positive_float, default=0.2, help="PPO clip range")
    p.add_argument("--ent-coef", type=finite_float, default=0.01, help="entropy coefficient")
    p.add_argument("--vf-coef", type=nonneg_float, default=0.5, help="value loss coefficient")
    p.add_argument("--max-grad-norm", type=positive_float, default=0.5, help="gradient-norm clip")
    p.add_argument("--hidden-sizes", type=positive_int, nargs="+", default=[256, 256], help="hidden widths (tanh)")
    p.add_argument("--normalize-reward", action=argparse.BooleanOptionalAction, default=True,
                   help="scale rewards by a running std of the discounted return (VecNormalize)")
    p.add_argument("--rho-min", type=nonneg_float, default=0.1, help="lower bound of the per-episode rho")
    p.add_argument("--rho-max", type=nonneg_float, default=0.8, help="upper bound of the per-episode rho")
    p.add_argument("--rho-values", type=nonneg_float, nargs="+", default=None,
                   help="draw rho from these values instead")
    p.add_argument("--seed", type=nonneg_int, default=1, help="seed")
    p.add_argument("--out", default=None, help="output directory (default: runs/ppo; with --resume, the resumed "
                                               "run's folder)")
    p.add_argument("--save-every", type=nonneg_int, default=100_000, help="checkpoint every this many steps (0: off)")
    p.add_argument("--resume", default=None,
                   help="checkpoint (.zip) to continue from; its stored hyper-parameters are used")
    p.add_argument("--force", action="store_true",
                   help="start over in an --out that already holds a run (not needed to --resume it in its own folder)")
    p.add_argument("--progress", action=argparse.BooleanOptionalAction, default=True, help="show a progress bar")
    p.add_argument("--torch-threads", type=positive_int, default=1, help="torch intra-op threads")
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


class ProgressBar(BaseCallback):
    """One tqdm bar over the environment steps (SB3's own bar needs the ``rich`` package)."""

    def __init__(self, total_steps: int) -> None:
        super().__init__()
        self.total_steps = int(total_steps)
        self.bar: tqdm | None = None

    def _on_training_start(self) -> None:
        start = min(self.num_timesteps, self.total_steps)
        self.bar = tqdm(total=self.total_steps, initial=start, unit="step", dynamic_ncols=True, desc="PPO")

    def _on_step(self) -> bool:
        assert self.bar is not None
        self.bar.update(min(self.num_timesteps, self.total_steps) - self.bar.n)
        return True

    def _on_training_end(self) -> None:
        if self.bar is not None:
            self.bar.close()


def run_folder(checkpoint: Path) -> Path:
    """The run folder of a checkpoint: the folder of ``ppo_final.zip``, or the one above ``checkpoints/``."""
    parent = checkpoint.resolve().parent
    return parent.parent if parent.name == "checkpoints" else parent


def vecnormalize_path(checkpoint: Path) -> Path:
    """The reward-normaliser file written with ``checkpoint`` (final or ``CheckpointCallback``)."""
    name = checkpoint.name
    if name.startswith("ppo_") and name.endswith("_steps.zip"):  # ppo_<n>_steps.zip
        return checkpoint.with_name("ppo_vecnormalize_" + name[len("ppo_"):-len(".zip")] + ".pkl")
    return checkpoint.with_name(checkpoint.stem + "_vecnormalize.pkl")


def main(argv: list[str] | None = None) -> Path:
    args = parse_args(argv)
    logging.basicConfig(level=getattr(logging, args.log_level.upper()), format="%(asctime)s %(name)s: %(message)s")
    torch.set_num_threads(args.torch_threads)
    resume = Path(args.resume) if args.resume else None
    out = Path(args.out) if args.out is not None else run_folder(resume) if resume is not None else Path("runs/ppo")
    own_run = resume is not None and run_folder(resume) == out.resolve()
    if (out / "ppo_final.zip").exists() and not args.force and not own_run:
        raise SystemExit(f"--out {out} already holds a run ({out / 'ppo_final.zip'}): continue it with --resume "
                         f"{out / 'ppo_final.zip'}, start over there with --force, or choose another --out")
    if resume is not None and not resume.is_file():
        raise SystemExit(f"--resume {resume}: no such checkpoint")
    norm_path = vecnormalize_path(resume) if resume is not None else None
    if norm_path is not None and args.normalize_reward and not norm_path.is_file():
        raise SystemExit(f"--resume {resume}: the reward normaliser {norm_path} is missing "
                         "(or pass --no-normalize-reward)")
    env_kwargs = json.loads(args.env_kwargs)
    if args.decision_interval is not None:
        env_kwargs["decision_interval"] = args.decision_interval
    _ensure_registered(args.env_id)
    world = world_of(args.env_id, env_kwargs)
    if world is not None:  # compile the kernels here, before the workers start and outside the progress bar's ETA
        warm_up([world], multi_agent=False)

    fns = [make_env(args, env_kwargs) for _ in range(args.n_envs)]
    venv: VecEnv = SubprocVecEnv(pinned_factories(fns, args.pin_workers)) if args.n_envs > 1 else DummyVecEnv(fns)
    venv.seed(args.seed)
    if args.normalize_reward:
        if norm_path is not None:
            venv = VecNormalize.load(str(norm_path), venv)
        else:
            venv = VecNormalize(venv, norm_obs=False, norm_reward=True, gamma=args.discount)

    if resume is not None:
        model = PPO.load(resume, env=venv, device="cpu", tensorboard_log=str(out / "tb"))
        logger.info("resumed from %s at %d steps", resume, model.num_timesteps)
    else:
        model = new_model(args, venv, out)
    callbacks: list[BaseCallback] = [ProgressBar(args.total_steps)] if args.progress else []
    if args.save_every:
        callbacks.append(CheckpointCallback(max(args.save_every // args.n_envs, 1), str(out / "checkpoints"),
                                            name_prefix="ppo", save_vecnormalize=args.normalize_reward))
    remaining = max(0, args.total_steps - model.num_timesteps)
    # Nothing is written into --out before the first reset (SB3 resets the envs before it writes logs or
    # checkpoints): a run that fails there leaves no trace that would make the corrected command refuse it.
    model.learn(remaining, callback=callbacks, tb_log_name="ppo", reset_num_timesteps=resume is None,
                progress_bar=False)
    out.mkdir(parents=True, exist_ok=True)
    final = out / "ppo_final.zip"
    model.save(final)
    if args.normalize_reward:
        venv.save(str(vecnormalize_path(final)))
    venv.close()
    logger.info("saved %s after %d steps", final, model.num_timesteps)
    return final


def new_model(args: argparse.Namespace, venv: VecEnv, out: Path) -> PPO:
    """A fresh SB3 PPO with the command line's hyper-parameters."""
    return PPO(
        "MlpPolicy", venv,
        learning_rate=args.learning_rate, n_steps=args.n_steps, batch_size=args.batch_size,
        n_epochs=args.n_epochs, gamma=args.discount, gae_lambda=args.gae_lambda, clip_range=args.clip_range,
        ent_coef=args.ent_coef, vf_coef=args.vf_coef, max_grad_norm=args.max_grad_norm,
        policy_kwargs={"net_arch": list(args.hidden_sizes), "activation_fn": torch.nn.Tanh},
        tensorboard_log=str(out / "tb"), seed=args.seed, device="cpu", verbose=0,
    )


if __name__ == "__main__":
    main()
