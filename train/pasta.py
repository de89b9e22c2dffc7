"""Train the PASTA gamma policy on a SOfAR environment.

Usage (from the repository root, with the package installed)::

    python train/pasta.py                                   # Laguna Seca, defaults
    python train/pasta.py --stack paper                     # with the paper's Algorithm 1 as controller
    python train/pasta.py --scenario interactive            # in the interactive world
    python train/pasta.py --quick                           # a short run that finishes episodes
    python train/pasta.py --n-envs 2 --total-steps 800000 --out runs/pasta_ls   # 2 worker processes
    python train/pasta.py --resume runs/pasta_ls/pasta_final.json --total-steps 1200000   # continue in place
    python train/pasta.py --n-envs 2 --backend local         # gymnasium's AsyncVectorEnv (lock-step) instead
    python train/pasta.py --backend ray --num-workers 4     # envs in Ray actors (pip install "sofar[ray]")
    python train/pasta.py --backend ray --address auto --num-workers 16 --n-envs 16   # on a Ray cluster
    python train/pasta.py --multi-agent --cars 4            # self-play: one shared policy drives 4 cars of a race
    python train/pasta.py --circuits LagunaSeca Monza Indianapolis Kentucky --n-envs 4   # one env per circuit
    tensorboard --logdir runs

Every PASTA hyper-parameter (``sofar_agents.PASTAConfig``) is also an option, e.g.
``--learning-rate 1e-4 --pcgrad --hidden-sizes 256 256``; ``--help`` lists them.

Per episode the opponent pace ratio rho is drawn uniformly from ``[--rho-min,
--rho-max]`` (the paper evaluates at 0.1, 0.3, 0.5, 0.65, 0.8), or from
``--rho-values`` when given. Outputs in ``--out``: ``tb/`` (TensorBoard),
``checkpoints/pasta_<steps>.{json,pt}`` every ``--save-every`` updates and
``pasta_final.{json,pt}``. ``--resume`` continues a run in its own folder (the default ``--out``
with ``--resume``); another ``--out`` that already holds a run (a ``pasta_final.json``) is refused
unless ``--force`` is given, which starts over there. After every update one console line reports the
mean returns of the last finished episodes per objective, by name.

Nothing is written into ``--out`` before the environments, the agent (or the checkpoint of ``--resume``)
and the first reset have been checked; a run that stops before its first update writes no
``pasta_final``. A run stopped (Ctrl-C) during an update saves the state before that update. A checkpoint
holds the generators' and the environments' state, so that ``--resume`` with the same environments and
``--n-envs`` continues bit-identically to a run that was not stopped (:mod:`sofar_agents.pasta.resume`).

``--quick`` is a preset for a first look (its time: ``results/first_ten_minutes.md``): 16384 steps
in rollouts of 512, 30 s episodes, 4 PPO epochs, output in ``runs/pasta_quick``; options
given explicitly win over it.

``--multi-agent`` trains one parameter-shared policy by self-play on the PettingZoo race
(:func:`sofar_env.multi_agent.parallel_env` on the circuit and world of ``--env-id``, ``--cars``
cars, ``--n-envs`` races): every car is one slot of the vector env
(:class:`sofar_agents.pasta.self_play.RaceVectorEnv`), so steps count car decisions, and a race
ends for all its cars when one car terminates. There is no rho (the opponents are the other
controlled cars, each with a speed factor drawn per race). With several races, each worker of
``--backend processes`` (or ``ray``) runs whole races.

With ``--n-envs`` above 1 the environments (and their solvers) run in ``--num-workers`` worker
processes of this machine (``--backend processes``, the default then), or in Ray actors
(``--backend ray``); each worker holds a copy of the policy and steps its envs without waiting
for the others at every step, the learner stays in this process. ``--backend local`` steps them
in a gymnasium ``AsyncVectorEnv`` instead (every worker one step, then a wait for all). A seeded
run gives the same checkpoints on every backend with the same ``--n-envs`` (see
:mod:`sofar_agents.pasta.actor_pool`); the backends differ only in speed.
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import json
import logging
import shlex
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any

import gymnasium as gym
import numpy as np
import torch
from torch.utils.tensorboard import SummaryWriter
from tqdm import tqdm
from tqdm.contrib.logging import logging_redirect_tqdm

from sofar_agents.cli import add_dataclass_options, check_dataclass_options
from sofar_agents.cli_types import int_at_least, nonneg_float, positive_int
from sofar_agents.pasta import PASTA, PASTAConfig
from sofar_agents.pasta.rollout import make_training_env
from sofar_agents.pasta.self_play import make_self_play_race
from sofar_agents.pasta.training_log import (check_out, code_commit, console_line, log_update, n_objectives,
                                             objective_names, run_folder)
from sofar_env.compile import warm_up, world_of
from sofar_env.configs.objectives import REFERENCE_PREFERENCE  # the objectives' registry
from sofar_env.scenarios import SCENARIOS
from sofar_env.stack.config import STACK_PRESETS
from sofar_env.tracks import TRACK_NAMES
from sofar_env.vector import async_vector_env, available_cpus

logger = logging.getLogger("train.pasta")


QUICK_RUN = {"total_steps": 16384, "out": "runs/pasta_quick", "save_every": 8}
"""Run options of ``--quick`` (applied to the options not given on the command line)."""
QUICK_PASTA = {"n_steps": 512, "n_epochs": 4}
"""PASTA hyper-parameters of ``--quick``."""
QUICK_EPISODE_S = 30.0
"""Episode length of ``--quick`` in simulated seconds (``race.duration``; default 200 s)."""
BACKENDS = ("local", "processes", "ray")
"""Values of ``--backend`` (see :attr:`Args.backend`)."""


@dataclass
class Args:
    """Run options (the PASTA hyper-parameters are added from ``PASTAConfig``)."""

    env_id: str = "SOfAR-LagunaSeca-v0"
    """Gymnasium id of the training environment (``module:id`` imports ``module`` first)."""
    env_kwargs: str = "{}"
    """Extra keyword arguments of ``gymnasium.make`` as a JSON object."""
    stack: str | None = None
    """Controller preset (``sofar_env.stack.STACK_PRESETS``; ``paper`` is the paper's Algorithm 1); passed as
    the ``stack`` key (default: the environment's, ``sofar``)."""
    scenario: str | None = None
    """World (``sofar_env.scenarios.SCENARIOS``); passed as the ``scenario`` key (default: the world of
    ``--env-id``)."""
    decision_interval: Annotated[int, positive_int] | None = None
    """If set, passed to the environment as ``decision_interval`` (simulator steps per action)."""
    circuits: list[str] | None = None
    """Train on several circuits of ``--env-id``'s world, passed as the ``track`` keyword: env i runs the circuit
    i modulo their number, so ``--n-envs`` must be a multiple of it (default: ``--env-id``'s circuit)."""
    total_steps: Annotated[int, positive_int] = 1_000_000
    """Environment steps to train for, counted over all envs (including resumed steps)."""
    n_envs: Annotated[int, positive_int] | None = None
    """Parallel environments (with ``--multi-agent``: races), in worker processes when > 1 (``--backend``);
    default 1, or ``--num-workers``."""
    pin_workers: bool = True
    """Pin each worker (of the ``AsyncVectorEnv``, or of ``--backend processes``) to a CPU of its own (Linux,
    and only when there are at least as many CPUs as workers): the same results, fewer stalls between lock-steps
    (``sofar_env.vector``)."""
    backend: str | None = None
    """Where the environments run: ``local`` (in this process with one env; a gymnasium ``AsyncVectorEnv``
    with several: every worker steps once, then waits for the others), ``processes`` (worker processes on
    this machine, each owning a slice of the envs, their solvers and a copy of the policy, stepping in chunks
    without a per-step barrier) or ``ray`` (the same in Ray actors, on this machine or a cluster); the learner
    stays here. Every backend gives the same checkpoints; default: ``processes`` with more than one env (with
    ``--multi-agent``: race) or with ``--num-workers``, else ``local``. Ray's start-up (the instance, then every
    worker's imports and environments) takes seconds, a large share of a short run such as ``--quick``: it pays
    off on long runs and on a cluster."""
    num_workers: Annotated[int, positive_int] | None = None
    """Workers with ``--backend processes`` or ``ray`` (one CPU each; default: one per env, with ``processes``
    at most one per CPU this process may use)."""
    address: str | None = None
    """Ray cluster to join with ``--backend ray``: ``auto`` or ``HOST:PORT`` (default:
    start a private local Ray instance with ``--num-workers`` CPUs)."""
    multi_agent: bool = False
    """Self-play on the PettingZoo race of ``--env-id``'s circuit and world: one shared policy drives every car."""
    cars: Annotated[int, int_at_least(2)] = 4
    """Controlled cars per race with ``--multi-agent``."""
    quick: bool = False
    """Preset for a first look (timed in results/first_ten_minutes.md): 16384 steps, rollouts of 512, 30 s
    episodes, 4 epochs, ``--out runs/pasta_quick``; explicit options win."""
    force: bool = False
    """Start over in an ``--out`` that already holds a run (its checkpoints are replaced); not needed to
    ``--resume`` a run in its own folder."""
    seed: int = 1
    """Seed of the agent and of the environments (env i is seeded with seed + i)."""
    out: str = "runs/pasta"
    """Output directory for TensorBoard logs and checkpoints (with ``--resume``: the resumed run's folder)."""
    resume: str | None = None
    """Checkpoint (``.json`` or ``.pt``) to continue training from."""
    save_every: int = 10
    """Write a checkpoint every this many updates (0: only at the end)."""
    preference: Annotated[list[float], nonneg_float] | None = None
    """Deployment preference w over the objectives (default: the reference's
    0.31 0.45 0.05 0.04 0.15 for the five SOfAR objectives, else uniform)."""
    rho_min: Annotated[float, nonneg_float] = 0.1
    """Lower bound of the per-episode opponent pace ratio."""
    rho_max: Annotated[float, nonneg_float] = 0.8
    """Upper bound of the per-episode opponent pace ratio."""
    rho_values: Annotated[list[float], nonneg_float] | None = None
    """If given, draw rho uniformly from these values instead of the interval."""
    torch_threads: Annotated[int, positive_int] = 1
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


def parse_args(argv: list[str] | None = None) -> tuple[Args, dict[str, Any]]:
    """Parse the command line into run options and PASTA config overrides (``--quick`` applied, checked).

    A value outside its option's argument type (a count below 1, a non-finite or out-of-range number),
    or hyper-parameters that do not fit together, is a usage error: message on stderr, exit status 2.
    """
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    add_dataclass_options(parser, Args, "run", choices={"stack": STACK_PRESETS, "scenario": SCENARIOS,
                                                         "circuits": TRACK_NAMES})
    add_dataclass_options(parser, PASTAConfig, "PASTA hyper-parameters")
    parser._option_string_actions["--mu-decay-steps"].help = (
        "Length of the linear decay of the target mu from --mu-max to --mu-min, in environment steps over "
        "all envs; mu stays at --mu-min afterwards (default: --total-steps of a new run; kept on --resume)")
    for action in parser._actions:  # "(default: None)" where the help already says what the default is
        if action.help and action.help.endswith(" (default: None)") and "default" in action.help[:-16]:
            action.help = action.help[:-16]
    ns = vars(parser.parse_args(argv))
    if ns["quick"]:
        for key, value in {**QUICK_RUN, **QUICK_PASTA}.items():
            if ns[key] is None:
                ns[key] = value
    if ns["out"] is None and ns["resume"] is not None:
        ns["out"] = str(run_folder(ns["resume"]))  # a resumed run continues in its own folder
    run_names = {f.name for f in dataclasses.fields(Args)}
    args = Args(**{k: v for k, v in ns.items() if k in run_names and v is not None})
    overrides = {k: v for k, v in ns.items() if k not in run_names and v is not None}
    if "hidden_sizes" in overrides:
        overrides["hidden_sizes"] = tuple(overrides["hidden_sizes"])
    if args.backend is None:
        several = args.num_workers is not None or (args.n_envs or 1) > 1
        # preference switches within an episode are made by the local collector only
        args.backend = "processes" if several and not overrides.get("preference_interval") else "local"
    if overrides.get("preference_interval") and args.backend != "local":
        parser.error("--preference-interval needs --backend local (the worker pools draw preferences per episode)")
    if args.backend not in BACKENDS:
        parser.error(f"--backend must be one of {', '.join(BACKENDS)}, got {args.backend!r}")
    if args.backend == "local" and args.num_workers is not None:
        parser.error("--num-workers needs --backend processes or ray")
    if args.backend != "ray" and args.address is not None:
        parser.error("--address needs --backend ray")
    if args.n_envs is None:
        args.n_envs = args.num_workers if args.num_workers is not None else 1
    if args.circuits is not None:
        if args.multi_agent:
            parser.error("--circuits trains single-car envs; --multi-agent races on --env-id's circuit")
        if len(set(args.circuits)) != len(args.circuits):
            parser.error(f"--circuits names a circuit twice: {' '.join(args.circuits)}")
        if args.n_envs % len(args.circuits):
            parser.error(f"--n-envs {args.n_envs} is not a multiple of the {len(args.circuits)} --circuits "
                         "(every circuit gets as many envs)")
    if args.resume is None:  # the hyper-parameters together (a resumed run checks them against its own)
        check_dataclass_options(parser, PASTAConfig, overrides)
    if args.num_workers is None and args.backend == "processes":
        args.num_workers = min(args.n_envs, available_cpus())  # more workers than CPUs only add switching
    elif args.num_workers is None and args.backend == "ray":
        args.num_workers = args.n_envs  # a cluster's CPUs are not this machine's
    if args.backend != "local":
        if args.num_workers > args.n_envs:
            parser.error(f"--num-workers {args.num_workers} exceeds --n-envs {args.n_envs} (each worker owns envs)")
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
    """Picklable thunk building one training env: vector reward kept in ``info["reward_vector"]``."""
    return functools.partial(make_training_env, env_id, env_kwargs, args.rho_min, args.rho_max, args.rho_values)


def env_kwargs_of(args: Args) -> dict[str, Any]:
    """The keyword arguments of ``gymnasium.make``: ``--env-kwargs`` plus ``--stack`` / ``--scenario``."""
    env_kwargs = json.loads(args.env_kwargs)
    if not isinstance(env_kwargs, dict):
        raise SystemExit("--env-kwargs must be a JSON object")
    for key in ("stack", "scenario"):
        if getattr(args, key) is not None:
            env_kwargs[key] = getattr(args, key)
    if args.quick:
        race = env_kwargs.setdefault("race", {})
        if isinstance(race, dict):
            race.setdefault("duration", QUICK_EPISODE_S)
    return env_kwargs


def race_of(env_id: str, env_kwargs: dict[str, Any]) -> tuple[Any, dict[str, Any]]:
    """The circuit and the other keyword arguments of the PettingZoo race matching ``env_id`` plus ``env_kwargs``."""
    kwargs = {**gym.spec(env_id).kwargs, **env_kwargs}
    track = kwargs.pop("track", None)
    if track is None:
        raise SystemExit(f"--multi-agent: {env_id!r} names no circuit; pass it as --env-kwargs '{{\"track\": NAME}}'")
    return track, kwargs


def make_vec_env(args: Args) -> Any:
    """The training envs: a gymnasium vector env (local backend), a :class:`ProcessEnvPool` or a :class:`RayEnvPool`."""
    env_kwargs = env_kwargs_of(args)
    if args.decision_interval is not None:
        env_kwargs["decision_interval"] = args.decision_interval
    assert args.n_envs is not None
    cars = None
    if args.multi_agent:
        track, race_kwargs = race_of(args.env_id, env_kwargs)
        fns = [functools.partial(make_self_play_race, track, args.cars, race_kwargs) for _ in range(args.n_envs)]
        cars = args.cars
        if args.backend == "local":
            from sofar_agents.pasta.self_play import RaceVectorEnv

            return RaceVectorEnv(fns)
    else:
        circuits = [{"track": c} for c in args.circuits] if args.circuits else [{}]
        fns = [make_env(args.env_id, {**env_kwargs, **circuits[i % len(circuits)]}, args) for i in range(args.n_envs)]
    if args.backend == "ray":
        from sofar_agents.pasta.ray_rollout import RayEnvPool

        assert args.num_workers is not None
        return RayEnvPool(fns, args.num_workers, address=args.address, cars_per_race=cars)
    if args.backend == "processes":
        from sofar_agents.pasta.process_rollout import ProcessEnvPool

        assert args.num_workers is not None
        return ProcessEnvPool(fns, args.num_workers, pin_workers=args.pin_workers, cars_per_race=cars)
    mode = gym.vector.AutoresetMode.SAME_STEP
    if args.n_envs > 1:
        return async_vector_env(fns, pin_workers=args.pin_workers, autoreset_mode=mode)
    return gym.vector.SyncVectorEnv(fns, autoreset_mode=mode)


# ---------------------------------------------------------------------------- main


def build_agent(args: Args, overrides: dict[str, Any], vec_env: Any) -> tuple[PASTA, float]:
    """The agent to train on ``vec_env`` (loaded from ``--resume``, or new) and the wall time of its earlier
    stages [s]; ``SystemExit`` or ``ValueError`` when it does not fit the env or the options."""
    obs_space, act_space = vec_env.single_observation_space, vec_env.single_action_space
    obs_dim = int(np.prod(obs_space.shape))
    k = n_objectives(vec_env)
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
        logger.info("resumed from %s at %d steps", args.resume, agent.num_timesteps)
        return agent, float(agent.metadata.get("wall_time_s", 0.0))
    overrides.setdefault("mu_decay_steps", args.total_steps)
    config = dataclasses.replace(PASTAConfig(), **overrides)
    preference = args.preference
    if preference is None and k == len(REFERENCE_PREFERENCE):
        preference = REFERENCE_PREFERENCE
    agent = PASTA(obs_dim, k, act_space.low, act_space.high, config, preference=preference, seed=args.seed,
                  objective_names=objective_names(vec_env))
    return agent, 0.0


def main(argv: list[str] | None = None) -> Path:
    args, overrides = parse_args(argv)
    logging.basicConfig(level=getattr(logging, args.log_level.upper()), format="%(asctime)s %(name)s: %(message)s")
    if args.backend == "ray":
        from sofar_agents.ray_support import require_ray

        try:
            require_ray(local=args.address is None)
        except ImportError as err:
            print(f"train/pasta.py: --backend ray: {err}", file=sys.stderr)
            raise SystemExit(2) from err
    torch.set_num_threads(args.torch_threads)
    out = Path(args.out)
    check_out(out, args.force, args.resume)
    t_start = time.time()

    # Everything that can fail is checked before anything is written to --out: the environments, the
    # agent (or the checkpoint it resumes) and the first reset (or the replay of the resumed episodes).
    ensure_registered(args.env_id)
    world = world_of(args.env_id, env_kwargs_of(args))
    if world is not None:  # compile the kernels here, before the workers start and outside the progress bar's ETA
        warm_up([world], multi_agent=args.multi_agent)
    vec_env = make_vec_env(args)
    try:
        agent, prev_wall = build_agent(args, overrides, vec_env)
        remaining = max(0, args.total_steps - agent.num_timesteps)
        if remaining:
            agent.prepare(vec_env)
    except BaseException:
        vec_env.close()
        raise
    out.mkdir(parents=True, exist_ok=True)

    run_meta = {
        "command": shlex.join(["python", "train/pasta.py", *(sys.argv[1:] if argv is None else argv)]),
        "code_commit": code_commit(Path(__file__).resolve().parent.parent),
        "seed": args.seed,
        "env_id": args.env_id,
        "env_kwargs": env_kwargs_of(args),
        "decision_interval": args.decision_interval,
        "circuits": args.circuits,
        "n_envs": args.n_envs,
        "pin_workers": args.pin_workers,
        "backend": args.backend,
        "num_workers": args.num_workers,
        "rho": None if args.multi_agent else (args.rho_values if args.rho_values is not None
                                              else [args.rho_min, args.rho_max]),
        "multi_agent": args.multi_agent,
        "cars": args.cars if args.multi_agent else None,
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

    pbar = tqdm(total=args.total_steps, initial=min(agent.num_timesteps, args.total_steps), unit="step",
                disable=not args.progress, dynamic_ncols=True, desc="PASTA")

    def callback(ag: PASTA, stats: dict[str, Any]) -> bool:
        log_update(writer, ag, stats)
        pbar.update(stats["rollout"].rewards.shape[0] * stats["rollout"].rewards.shape[1])
        logger.info("%s", console_line(ag, stats, args.total_steps))
        if args.save_every and ag.num_updates % args.save_every == 0:
            path = save(out / "checkpoints" / f"pasta_{ag.num_timesteps:010d}")
            logger.debug("checkpoint %s", path)
        return True

    start_updates, completed = agent.num_updates, False
    try:
        with logging_redirect_tqdm():  # log lines above the one progress bar, not through it
            agent.learn(vec_env, remaining, callback=callback, log_interval=0)
        completed = True
    finally:
        pbar.close()
        if completed or agent.num_updates > start_updates:  # an interrupted update was undone by learn()
            final = save(out / "pasta_final")
        else:
            logger.warning("stopped before the first update: %s not written", out / "pasta_final")
        writer.close()
        vec_env.close()
        if args.track:
            import wandb

            wandb.finish()
    logger.info("saved %s after %d steps (%.0f s)", final, agent.num_timesteps, time.time() - t_start)
    return final


if __name__ == "__main__":
    main()
