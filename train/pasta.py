"""Train the PASTA gamma policy on a SOfAR environment.

Usage (from the repository root, with the package installed)::

    python train/pasta.py                                   # Laguna Seca, defaults
    python train/pasta.py --stack paper                     # with the paper's Algorithm 1 as controller
    python train/pasta.py --scenario interactive            # in the interactive world
    python train/pasta.py --n-envs 2 --total-steps 800000 --out runs/pasta_ls
    python train/pasta.py --resume runs/pasta_ls/pasta_final.json --total-steps 1200000
    tensorboard --logdir runs

Every PASTA hyper-parameter (``sofar_agents.PASTAConfig``) is also an option, e.g.
``--learning-rate 1e-4 --pcgrad --hidden-sizes 256 256``; ``--help`` lists them.

Per episode the opponent pace ratio rho is drawn uniformly from ``[--rho-min,
--rho-max]`` (the paper evaluates at 0.1, 0.3, 0.5, 0.65, 0.8), or from
``--rho-values`` when given. Outputs in ``--out``: ``tb/`` (TensorBoard),
``checkpoints/pasta_<steps>.{json,pt}`` every ``--save-every`` updates and
``pasta_final.{json,pt}``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import logging
import shlex
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from torch.utils.tensorboard import SummaryWriter
from tqdm import tqdm

from sofar_agents.cli import add_dataclass_options
from sofar_agents.pasta import PASTA, PASTAConfig
from sofar_agents.wrappers import LinearReward, RandomRhoReset

logger = logging.getLogger("train.pasta")

REFERENCE_PREFERENCE = (0.31, 0.45, 0.05, 0.04, 0.15)
"""Deployment preference of the reference implementation, in the order of the SOfAR
objectives (safety, overtakes, progress, barrier_margin, gamma_smoothness)."""


@dataclass
class Args:
    """Run options (the PASTA hyper-parameters are added from ``PASTAConfig``)."""

    env_id: str = "SOfAR-LagunaSeca-v0"
    """Gymnasium id of the training environment (``module:id`` imports ``module`` first)."""
    env_kwargs: str = "{}"
    """Extra keyword arguments of ``gymnasium.make`` as a JSON object."""
    stack: str | None = None
    """Controller preset, ``sofar`` or ``paper`` (the paper's Algorithm 1); passed as the ``stack`` key."""
    scenario: str | None = None
    """World, ``paper`` or ``interactive``; passed as the ``scenario`` key."""
    decision_interval: int | None = None
    """If set, passed to the environment as ``decision_interval`` (simulator steps per action)."""
    total_steps: int = 1_000_000
    """Environment steps to train for, counted over all envs (including resumed steps)."""
    n_envs: int = 1
    """Parallel environments (``AsyncVectorEnv`` subprocesses when > 1)."""
    seed: int = 1
    """Seed of the agent and of the environments (env i is seeded with seed + i)."""
    out: str = "runs/pasta"
    """Output directory for TensorBoard logs and checkpoints."""
    resume: str | None = None
    """Checkpoint (``.json`` or ``.pt``) to continue training from."""
    save_every: int = 10
    """Write a checkpoint every this many updates (0: only at the end)."""
    preference: list[float] | None = None
    """Deployment preference w over the objectives (default: the reference's
    0.31 0.45 0.05 0.04 0.15 for the five SOfAR objectives, else uniform)."""
    rho_min: float = 0.1
    """Lower bound of the per-episode opponent pace ratio."""
    rho_max: float = 0.8
    """Upper bound of the per-episode opponent pace ratio."""
    rho_values: list[float] | None = None
    """If given, draw rho uniformly from these values instead of the interval."""
    torch_threads: int = 1
    """Torch intra-op threads of the learner."""
    progress: bool = True
    """Show a tqdm progress bar."""
    track: bool = False
    """Also log to Weights & Biases (needs the ``wandb`` package)."""
    wandb_project: str = "sofar"
    """Weights & Biases project name."""
    wandb_entity: str | None = None
    """Weights & Biases entity (team)."""
    log_level: str = "INFO"
    """Python logging level."""


# ---------------------------------------------------------------------------- arguments


def _code_commit() -> str | None:
    """The git commit of the source tree this script runs from (``+dirty`` if modified), if known."""
    import subprocess

    root = Path(__file__).resolve().parent.parent
    try:
        commit = subprocess.run(["git", "-C", str(root), "rev-parse", "HEAD"], capture_output=True, text=True,
                                timeout=5, check=True).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(root), "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True, timeout=5, check=True).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return None
    return commit + ("+dirty" if dirty else "")


def parse_args(argv: list[str] | None = None) -> tuple[Args, dict[str, Any]]:
    """Parse the command line into run options and PASTA config overrides."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    add_dataclass_options(parser, Args, "run")
    add_dataclass_options(parser, PASTAConfig, "PASTA hyper-parameters")
    ns = vars(parser.parse_args(argv))
    run_names = {f.name for f in dataclasses.fields(Args)}
    args = Args(**{k: v for k, v in ns.items() if k in run_names and v is not None})
    overrides = {k: v for k, v in ns.items() if k not in run_names and v is not None}
    if "hidden_sizes" in overrides:
        overrides["hidden_sizes"] = tuple(overrides["hidden_sizes"])
    return args, overrides


# ---------------------------------------------------------------------------- environments


def ensure_registered(env_id: str) -> None:
    """Make sure ``env_id`` is registered, importing ``sofar_env`` if needed."""
    if ":" in env_id or env_id in gym.registry:
        return
    try:
        import sofar_env  # noqa: F401  (registers the SOfAR ids)
    except ImportError as err:
        raise SystemExit(f"cannot import sofar_env to register {env_id!r}: {err}") from err
    if env_id not in gym.registry:
        try:
            from sofar_env.registration import register_envs

            register_envs()
        except ImportError:
            pass
    if env_id not in gym.registry:
        raise SystemExit(f"unknown environment id {env_id!r}; registered SOfAR ids: "
                         f"{sorted(k for k in gym.registry if 'SOfAR' in k)}")


def make_env(env_id: str, env_kwargs: dict[str, Any], args: Args) -> Any:
    """Thunk building one training env: vector reward kept in ``info["reward_vector"]``."""

    def thunk() -> gym.Env:
        ensure_registered(env_id)
        env = gym.make(env_id, reward_mode="vector", **env_kwargs)
        env = RandomRhoReset(env, args.rho_min, args.rho_max, args.rho_values)
        return LinearReward(env)

    return thunk


def env_kwargs_of(args: Args) -> dict[str, Any]:
    """The keyword arguments of ``gymnasium.make``: ``--env-kwargs`` plus ``--stack`` / ``--scenario``."""
    env_kwargs = json.loads(args.env_kwargs)
    if not isinstance(env_kwargs, dict):
        raise SystemExit("--env-kwargs must be a JSON object")
    for key in ("stack", "scenario"):
        if getattr(args, key) is not None:
            env_kwargs[key] = getattr(args, key)
    return env_kwargs


def make_vec_env(args: Args) -> gym.vector.VectorEnv:
    env_kwargs = env_kwargs_of(args)
    if args.decision_interval is not None:
        env_kwargs["decision_interval"] = args.decision_interval
    fns = [make_env(args.env_id, env_kwargs, args) for _ in range(args.n_envs)]
    mode = gym.vector.AutoresetMode.SAME_STEP
    if args.n_envs > 1:
        return gym.vector.AsyncVectorEnv(fns, autoreset_mode=mode)
    return gym.vector.SyncVectorEnv(fns, autoreset_mode=mode)


def _objective_names(vec_env: gym.vector.VectorEnv) -> tuple[str, ...] | None:
    try:
        names = vec_env.get_attr("objective_names")[0]
        return tuple(str(n) for n in names)
    except (AttributeError, IndexError, TypeError):
        return None


def _n_objectives(vec_env: gym.vector.VectorEnv) -> int:
    try:
        space = vec_env.get_attr("reward_space")[0]
        return int(np.prod(space.shape))
    except (AttributeError, IndexError, TypeError) as err:
        raise SystemExit("the environment must declare env.unwrapped.reward_space") from err


# ---------------------------------------------------------------------------- logging


def _log_update(writer: SummaryWriter, agent: PASTA, stats: dict[str, Any]) -> None:
    step = agent.num_timesteps
    names = agent.objective_names
    for key in ("policy_loss", "value_loss", "entropy", "approx_kl", "clipfrac", "log_std"):
        writer.add_scalar(f"losses/{key}", stats[key], step)
    writer.add_scalar("pasta/mu", stats["mu"], step)
    writer.add_scalar("pasta/conflict_ratio", stats["conflict_ratio"], step)
    writer.add_scalar("charts/sps", stats["sps"], step)
    writer.add_scalar("charts/epochs", stats["epochs"], step)
    for j, name in enumerate(names):
        writer.add_scalar(f"attention/{name}", stats["attention"][j], step)
        writer.add_scalar(f"regret/{name}", stats["regret"][j], step)
        writer.add_scalar(f"return_scale/{name}", stats["return_scale"][j], step)
        ev = stats["explained_variance"][j]
        if np.isfinite(ev):
            writer.add_scalar(f"explained_variance/{name}", ev, step)
    buffer = stats["rollout"]
    writer.add_histogram("actions/gamma", buffer.actions.reshape(-1), step)
    writer.add_scalar("actions/gamma_mean", float(buffer.actions.mean()), step)
    episodes = stats["episodes"]
    if episodes:
        returns = np.array([e["returns"] for e in episodes])
        for j, name in enumerate(names):
            writer.add_scalar(f"episode_return/{name}", returns[:, j].mean(), step)
        writer.add_scalar("episode_return/preference_weighted", float((returns @ agent.preference).mean()), step)
        writer.add_scalar("charts/episode_length", np.mean([e["length"] for e in episodes]), step)
        writer.add_scalar("charts/episodes", len(episodes), step)
        for key, tag in (("is_success", "success_rate"), ("overtakes", "overtakes"), ("laps", "laps"),
                         ("collision", "collision_rate"), ("off_track", "off_track_rate")):
            vals = [e[key] for e in episodes if key in e]
            if vals:
                writer.add_scalar(f"charts/{tag}", float(np.mean(vals)), step)


# ---------------------------------------------------------------------------- main


def main(argv: list[str] | None = None) -> Path:
    args, overrides = parse_args(argv)
    logging.basicConfig(level=getattr(logging, args.log_level.upper()), format="%(asctime)s %(name)s: %(message)s")
    torch.set_num_threads(args.torch_threads)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    t_start = time.time()

    ensure_registered(args.env_id)
    vec_env = make_vec_env(args)
    obs_space, act_space = vec_env.single_observation_space, vec_env.single_action_space
    obs_dim = int(np.prod(obs_space.shape))
    k = _n_objectives(vec_env)
    names = _objective_names(vec_env)

    if args.resume:
        agent = PASTA.load(args.resume)
        if (agent.obs_dim, agent.n_objectives) != (obs_dim, k):
            raise SystemExit(f"{args.resume}: checkpoint has obs_dim {agent.obs_dim} and {agent.n_objectives} "
                             f"objectives, the environment {obs_dim} and {k}")
        if overrides:
            try:
                agent.reconfigure(**overrides)
            except ValueError as err:
                raise SystemExit(f"--resume: {err}") from err
        if args.preference is not None:
            agent.preference = agent._check_preference(args.preference)
        prev_wall = float(agent.metadata.get("wall_time_s", 0.0))
        logger.info("resumed from %s at %d steps", args.resume, agent.num_timesteps)
    else:
        overrides.setdefault("mu_decay_steps", args.total_steps)
        config = dataclasses.replace(PASTAConfig(), **overrides)
        preference = args.preference
        if preference is None and k == len(REFERENCE_PREFERENCE):
            preference = REFERENCE_PREFERENCE
        agent = PASTA(obs_dim, k, act_space.low, act_space.high, config, preference=preference, seed=args.seed,
                      objective_names=names)
        prev_wall = 0.0

    run_meta = {
        "command": shlex.join(["python", "train/pasta.py", *(sys.argv[1:] if argv is None else argv)]),
        "code_commit": _code_commit(),
        "seed": args.seed,
        "env_id": args.env_id,
        "env_kwargs": env_kwargs_of(args),
        "decision_interval": args.decision_interval,
        "n_envs": args.n_envs,
        "rho": args.rho_values if args.rho_values is not None else [args.rho_min, args.rho_max],
        "resumed_from": args.resume,
    }
    history = list(agent.metadata.get("history", []))
    history.append(run_meta)
    agent.metadata.update(run_meta)
    agent.metadata["history"] = history  # every training stage (first run and resumes), oldest first

    if args.track:
        try:
            import wandb
        except ImportError as err:
            raise SystemExit("--track needs the wandb package (pip install wandb)") from err
        wandb.init(project=args.wandb_project, entity=args.wandb_entity, sync_tensorboard=True,
                   config={**dataclasses.asdict(args), **agent.config.to_dict()}, name=out.name, save_code=True)
    writer = SummaryWriter(str(out / "tb"))
    rows = [*dataclasses.asdict(args).items(), *agent.config.to_dict().items()]
    writer.add_text("hyperparameters", "|param|value|\n|-|-|\n" + "\n".join(f"|{k_}|{v}|" for k_, v in rows))

    def save(path: Path) -> Path:
        meta = {"wall_time_s": prev_wall + time.time() - t_start, "num_timesteps": agent.num_timesteps}
        return agent.save(path, metadata=meta)

    remaining = max(0, args.total_steps - agent.num_timesteps)
    pbar = tqdm(total=remaining, unit="step", disable=not args.progress, dynamic_ncols=True)

    def callback(ag: PASTA, stats: dict[str, Any]) -> bool:
        _log_update(writer, ag, stats)
        pbar.update(stats["rollout"].rewards.shape[0] * stats["rollout"].rewards.shape[1])
        pbar.set_postfix(mu=f"{stats['mu']:.2f}", conflict=f"{stats['conflict_ratio']:.2f}", refresh=False)
        if args.save_every and ag.num_updates % args.save_every == 0:
            path = save(out / "checkpoints" / f"pasta_{ag.num_timesteps:010d}")
            logger.debug("checkpoint %s", path)
        return True

    try:
        agent.learn(vec_env, remaining, callback=callback)
    finally:
        pbar.close()
        final = save(out / "pasta_final")
        writer.close()
        vec_env.close()
        if args.track:
            import wandb

            wandb.finish()
    logger.info("saved %s after %d steps (%.0f s)", final, agent.num_timesteps, time.time() - t_start)
    return final


if __name__ == "__main__":
    main()
