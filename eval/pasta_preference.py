"""Does PASTA's preference input move its gamma, and which of its gammas cost pace? Three measurements.

    python eval/pasta_preference.py probe                          # every variant, 2 seeds, 40,000 steps each
    python eval/pasta_preference.py probe --variants shipped "mu 0.1, mid start" --steps 120000
    python eval/pasta_preference.py respond --policy sofar_agents/checkpoints/pasta_lagunaseca_interactive.json \
        --scenario interactive --opponents 8

``probe`` trains PASTA on the small trade-off environment of
:mod:`sofar_agents.evaluation.preference_probe` (no MPC: a run of 40,000 steps takes about a minute)
with the shipped training recipe changed one factor at a time, and reports the trained policy's mean gamma
at safety weights 0.1 ... 0.9 (overtakes 0.9 minus it, 0.1 / 3 for the other three objectives). A policy
whose preference input works chooses a lower gamma as the safety weight grows. Writes
``<out>/probe.md`` and ``probe.json``; rerunning skips the (variant, seed, steps) already in the JSON.

``respond`` reads a trained checkpoint on real states: it drives seeded episodes of a world at fixed
gammas, records the observations, and reports the policy's deterministic gamma per preference over them
(mean, 10th and 90th percentile).

``push`` collects rollouts of a checkpoint in its training world (preferences drawn as in training) and
reports, per safety-weight bin, which objective pushes the mean gamma up or down and how hard
(:mod:`sofar_agents.evaluation.objective_push`). The rollouts are the ones training would have collected
next (the checkpoint's random state and seeds), so a rerun gives the same table:

    python eval/pasta_preference.py push --policy runs/morl/pasta_final.json --scenario interactive \
        --opponents 8 --rollouts 6
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import sys
from pathlib import Path

import numpy as np

from sofar_agents.cli_types import float_in, gamma_value, nonneg_int, positive_int
from sofar_agents.evaluation.files import write_text_atomic
from sofar_agents.evaluation.gamma_floor import FLOOR_GAMMAS, WHERES
from sofar_agents.evaluation.protocol import RHOS, TRACKS
from sofar_agents.evaluation.preference_probe import (
    PROBE_SAFETY_WEIGHTS,
    PROBE_VARIANTS,
    preference_response,
    run_probe,
    safety_preferences,
)

logger = logging.getLogger("pasta_preference")


def probe(args: argparse.Namespace) -> None:
    import torch

    torch.set_num_threads(1)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    store = out / "probe.json"
    rows = json.loads(store.read_text())["runs"] if store.exists() else []
    done = {(r["variant"], r["seed"], r["steps_requested"]) for r in rows}
    for variant in args.variants:
        for seed in args.seeds:
            if (variant, seed, args.steps) in done:
                continue
            res = run_probe(variant, seed, args.steps)
            rows.append({"variant": variant, "seed": seed, "steps_requested": args.steps, "steps": res.steps,
                         "mean_gamma": res.response.mean.round(4).tolist(),
                         "p10": res.response.p10.round(4).tolist(), "p90": res.response.p90.round(4).tolist(),
                         "spread": round(res.response.spread, 4), "monotone": res.response.monotone(),
                         "final_mu": round(res.final_mu, 4),
                         "final_attention": [round(a, 4) for a in res.final_attention],
                         "wall_time_s": round(res.wall_time, 1)})
            logger.info("%s seed %d: mean gamma %s (spread %.3f), mu %.3f", variant, seed,
                        rows[-1]["mean_gamma"], res.response.spread, res.final_mu)
            write_text_atomic(store, json.dumps({"safety_weights": list(PROBE_SAFETY_WEIGHTS), "runs": rows}, indent=1))
    lines = ["# Does the preference move the gamma? PASTA on the trade-off environment", "",
             "Mean deterministic gamma over 11 traffic densities at each safety weight (overtakes 0.9 minus it); "
             "spread = largest minus smallest mean. Command: `python eval/pasta_preference.py probe` (see "
             "`sofar_agents/evaluation/preference_probe.py` for the environment and the variants).", "",
             "| variant | seed | steps | " + " | ".join(f"safety {w:g}" for w in PROBE_SAFETY_WEIGHTS)
             + " | spread | monotone | final mu | wall [s] |",
             "|---|---:|---:|" + "---:|" * len(PROBE_SAFETY_WEIGHTS) + "---:|:---:|---:|---:|"]
    for r in sorted(rows, key=lambda r: (list(PROBE_VARIANTS).index(r["variant"])
                                         if r["variant"] in PROBE_VARIANTS else 99, r["steps"], r["seed"])):
        lines.append(f"| {r['variant']} | {r['seed']} | {r['steps']:,} | "
                     + " | ".join(f"{g:.3f}" for g in r["mean_gamma"])
                     + f" | {r['spread']:.3f} | {'yes' if r['monotone'] else 'no'} | {r['final_mu']:.2f} "
                       f"| {r['wall_time_s']:.0f} |")
    write_text_atomic(out / "probe.md", "\n".join(lines) + "\n")
    sys.stdout.write("\n".join(lines) + "\n")


def respond(args: argparse.Namespace) -> None:
    import gymnasium as gym

    import sofar_env  # noqa: F401  (registers the ids)
    from sofar_agents.pasta import PASTA

    agent = PASTA.load(args.policy)
    kwargs = {"scenario": args.scenario}
    if args.opponents is not None:
        kwargs["n_opponents"] = args.opponents
    env = gym.make(args.env_id, **kwargs)
    observations = []
    for i, gamma in enumerate(args.gammas):
        for ep in range(args.episodes):
            obs, _ = env.reset(seed=args.seed + 1000 * i + ep, options={"rho": args.rho})
            for _ in range(args.steps):
                observations.append(obs)
                obs, _, terminated, truncated, _ = env.step(np.array([gamma], dtype=np.float32))
                if terminated or truncated:
                    break
    env.close()
    resp = preference_response(agent, np.asarray(observations), safety_preferences(args.safety_weights))
    sys.stdout.write(f"{len(observations)} states of {args.env_id} ({args.scenario}), policy {args.policy}\n\n"
                     "| safety weight | mean gamma | 10th pct | 90th pct |\n|---:|---:|---:|---:|\n")
    for w, m, lo, hi in zip(args.safety_weights, resp.mean, resp.p10, resp.p90):
        sys.stdout.write(f"| {w:g} | {m:.3f} | {lo:.3f} | {hi:.3f} |\n")


def push(args: argparse.Namespace) -> None:
    import functools

    import gymnasium as gym
    import torch

    from sofar_agents.evaluation.objective_push import objective_push, pool_bins, push_table
    from sofar_agents.pasta import PASTA
    from sofar_agents.pasta.rollout import RolloutCollector, make_training_env

    torch.set_num_threads(1)
    agent = PASTA.load(args.policy)
    kwargs: dict = {"scenario": args.scenario}
    if args.opponents is not None:
        kwargs["n_opponents"] = args.opponents
    fns = [functools.partial(make_training_env, args.env_id, kwargs, args.rho_min, args.rho_max)
           for _ in range(args.n_envs)]
    venv = gym.vector.SyncVectorEnv(fns, autoreset_mode=gym.vector.AutoresetMode.SAME_STEP)
    collector = RolloutCollector()
    runs = []
    try:
        for i in range(args.rollouts):
            buffer = collector.collect(agent, venv, agent.config.n_steps)
            runs.append(objective_push(agent, buffer))
            ends = sum(bool(e.get("collision")) or bool(e.get("off_track")) for e in buffer.episodes)
            logger.info("rollout %d of %d: %d episodes ended, %d by a collision or off-track", i + 1,
                        args.rollouts, len(buffer.episodes), ends)
    finally:
        venv.close()
    sys.stdout.write(f"{args.rollouts} rollouts of {args.n_envs} x {agent.config.n_steps} steps in {args.env_id} "
                     f"({args.scenario}), policy {args.policy}\n\n"
                     + push_table(pool_bins(runs), agent.objective_names))


def floor(args: argparse.Namespace) -> None:
    from sofar_agents.evaluation.gamma_floor import GammaFloor, run_floor_study
    from sofar_agents.evaluation.pareto import preference_family
    from sofar_agents.evaluation.sweep import incomplete_message
    from sofar_agents.policies import NAMED_POLICIES, named_policy_path

    policy = str(named_policy_path(args.policy)) if args.policy in NAMED_POLICIES else args.policy
    floors = [GammaFloor(args.floor, where, args.radius) for where in args.where]
    report = run_floor_study(policy, preference_family([args.safety_weight])[0], floors, args.out,
                             gammas=args.gammas, tracks=args.tracks, rhos=args.rhos, episodes=args.episodes,
                             base_seed=args.seed, workers=args.workers, stack=args.stack,
                             scenario=args.scenario, n_opponents=args.opponents, trace=args.trace)
    sys.stdout.write(report.markdown)
    if report.stats.unfinished:
        logger.error(incomplete_message(report.stats, args.out))
        raise SystemExit(1)


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="command", required=True)
    pr = sub.add_parser("probe", help="train on the trade-off environment, one factor at a time")
    pr.add_argument("--variants", nargs="+", default=list(PROBE_VARIANTS), choices=list(PROBE_VARIANTS),
                    metavar="NAME", help=f"variants (default all: {'; '.join(PROBE_VARIANTS)})")
    pr.add_argument("--seeds", nargs="+", type=nonneg_int, default=[0, 1], help="agent seeds (default 0 1)")
    pr.add_argument("--steps", type=positive_int, default=40_000, help="env steps per run (default 40000)")
    pr.add_argument("--out", default="results/pasta_preference", help="output folder")
    rs = sub.add_parser("respond", help="a checkpoint's gamma per preference on recorded states")
    rs.add_argument("--policy", required=True, help="PASTA checkpoint (.json)")
    rs.add_argument("--env-id", default="SOfAR-LagunaSeca-v0")
    rs.add_argument("--scenario", default="interactive")
    rs.add_argument("--opponents", type=nonneg_int, default=None)
    rs.add_argument("--rho", type=float_in(0.0, 1.0), default=0.5, help="opponents' pace ratio (default 0.5)")
    rs.add_argument("--gammas", nargs="+", type=gamma_value, default=[0.05, 0.3],
                    help="fixed gammas the recorded episodes are driven with (default 0.05 0.3)")
    rs.add_argument("--episodes", type=positive_int, default=2, help="episodes per gamma (default 2)")
    rs.add_argument("--steps", type=positive_int, default=200, help="decisions recorded per episode (default 200)")
    rs.add_argument("--seed", type=nonneg_int, default=9100)
    rs.add_argument("--safety-weights", nargs="+", type=float_in(0.0, 0.9),
                    default=[0.1, 0.2, 0.3, 0.45, 0.6, 0.75, 0.9],
                    help="safety weights in [0, 0.9]; overtakes get 0.9 minus each (default 0.1 0.2 0.3 0.45 0.6 0.75 0.9)")
    pu = sub.add_parser("push", help="which objective pushes a checkpoint's gamma which way, per preference")
    pu.add_argument("--policy", required=True, help="PASTA checkpoint (.json)")
    pu.add_argument("--env-id", default="SOfAR-LagunaSeca-v0")
    pu.add_argument("--scenario", default="interactive")
    pu.add_argument("--opponents", type=nonneg_int, default=None)
    pu.add_argument("--rho-min", type=float_in(0.0, 1.0), default=0.1)
    pu.add_argument("--rho-max", type=float_in(0.0, 1.0), default=0.8)
    pu.add_argument("--n-envs", type=positive_int, default=2, help="environments per rollout (default 2)")
    pu.add_argument("--rollouts", type=positive_int, default=6, help="rollouts (default 6)")
    fl = sub.add_parser("floor", help="a checkpoint with its gamma floored in chosen states, on seeded episodes")
    fl.add_argument("--policy", required=True, help="PASTA checkpoint (.json) or the name of a shipped policy")
    fl.add_argument("--safety-weight", type=float_in(0.0, 0.9), default=0.1,
                    help="the preference: safety this, overtakes 0.9 minus it (default 0.1, pace first)")
    fl.add_argument("--floor", type=gamma_value, default=0.15, help="the gamma floor (default 0.15)")
    fl.add_argument("--where", nargs="+", choices=list(WHERES), default=list(WHERES),
                    help="where the floor holds: every step, with no opponent within --radius, with one (default all)")
    fl.add_argument("--radius", type=float_in(0.1, 1000.0), default=20.0,
                    help="distance to the nearest opponent that separates near from far [m] (default 20)")
    fl.add_argument("--gammas", nargs="*", type=gamma_value, default=list(FLOOR_GAMMAS),
                    help=f"fixed gammas run on the same episodes (default {' '.join(map(str, FLOOR_GAMMAS))})")
    fl.add_argument("--scenario", default="interactive")
    fl.add_argument("--opponents", type=nonneg_int, default=None)
    fl.add_argument("--stack", default="sofar", help="controller preset (default: the default controller)")
    fl.add_argument("--tracks", nargs="+", choices=list(TRACKS), default=list(TRACKS))
    fl.add_argument("--rhos", nargs="+", type=float_in(0.0, 1.0), default=list(RHOS))
    fl.add_argument("--episodes", type=positive_int, default=2, help="episodes per (track, rho) (default 2)")
    fl.add_argument("--seed", type=nonneg_int, default=0, help="base seed of the episodes (default 0)")
    fl.add_argument("--workers", type=positive_int, default=1)
    fl.add_argument("--trace", action="store_true",
                    help="also record every control step (floor_trace.csv) and report gamma near and away from cars")
    fl.add_argument("--out", required=True, help="output folder (floor_episodes.csv, floor.md; resumes)")
    return p.parse_args(argv)


def main(argv: list[str] | None = None) -> None:
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s: %(message)s")
    args = parse_args(argv)
    {"probe": probe, "respond": respond, "push": push, "floor": floor}[args.command](args)


if __name__ == "__main__":
    main()
