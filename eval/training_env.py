"""Give a checkpoint trained before checkpoints recorded their training environment that record, by replay.

A checkpoint written by ``train/pasta.py`` records the configuration hash of its training environment
(``training.env_config_hash``). Older ones record only the command, the environment's keyword arguments and
the commit of the code: their training environment is known by name ("the default controller of commit X"),
and the default has moved since. This tool recovers it by value and proves it:

1. ``record`` replays seeded episodes of the training environment of a checkpoint (``gymnasium.make(env_id,
   reward_mode="vector", **env_kwargs)``, or the PettingZoo race of a self-play run) with a gamma that sweeps
   its range, and writes observations, vector rewards and ends of episode to one ``.npz``. Run it twice: once
   under a checkout of the commit the checkpoint was trained at (``PYTHONPATH=OLD_CHECKOUT``), with the
   keyword arguments as recorded; once under the current code with the versioned name of what the default
   was then (``--set stack=sofar-1``).
2. ``backfill`` compares each pair of recordings to the bit (one pair per training stage of a resumed run, the
   checkpoint's own environment last) and writes the checkpoint's sidecar ``<stem>.training_env.json``
   atomically: ``env_config_reconstructed`` (what was replayed where, whether it was identical, the stages no
   checkout can replay), with ``env_config_hash`` and ``env_config`` of the keyword arguments as named today when
   the last pair is identical. The checkpoint's own files stay as they are: their SHA-1 is the policy id its
   tables carry (:mod:`sofar_agents.pasta.env_reconstruction`)::

    git worktree add /tmp/old 3134d234bd36 --detach
    PYTHONPATH=/tmp/old python eval/training_env.py record --checkpoint CKPT.json --out /tmp/then.npz
    python eval/training_env.py record --checkpoint CKPT.json --set stack=sofar-1 --out /tmp/now.npz
    python eval/training_env.py backfill CKPT.json --evidence /tmp/then.npz /tmp/now.npz

``record`` imports nothing of this project but ``sofar_env``'s public constructors (gymnasium ids,
``sofar_env.multi_agent.parallel_env``), so that it runs under older checkouts too; it records which
``sofar_env`` it ran and that checkout's commit.
"""

from __future__ import annotations

import argparse
import json
import logging
import shlex
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

logger = logging.getLogger("training_env")

RHOS = (0.2, 0.5, 0.8)
"""Opponent pace ratios of the recorded single-car episodes, in turn (training draws one per episode)."""


def gamma_schedule(step: int, episode: int) -> float:
    """A gamma that sweeps [0.05, 1] and differs per episode (deterministic)."""
    return float(0.05 + 0.95 * (0.5 + 0.5 * np.sin(0.13 * step + 1.7 * episode)))


def count(text: str) -> int:
    """An argument type: a positive whole number (its own, so that ``record`` runs under older checkouts)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive whole number, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected a positive whole number, got {value}")
    return value


def parse_sets(items: list[str]) -> dict[str, Any]:
    """``KEY=VALUE`` pairs; a VALUE that parses as JSON is taken as such (``n_opponents=8``), else a string."""
    out: dict[str, Any] = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key:
            raise SystemExit(f"--set expects KEY=VALUE, got {item!r}")
        try:
            out[key] = json.loads(value)
        except json.JSONDecodeError:
            out[key] = value
    return out


def training_of(checkpoint: Path) -> dict[str, Any]:
    """The checkpoint JSON's ``training`` object (``env_id``, ``env_kwargs``, ``multi_agent``, ``cars``, ...)."""
    meta = json.loads(checkpoint.read_text())
    training = meta.get("training")
    if not isinstance(training, dict) or not training.get("env_id"):
        raise SystemExit(f"{checkpoint}: no training.env_id recorded: not a checkpoint of train/pasta.py")
    return training


def _code_of(module: Any) -> dict[str, str]:
    root = Path(module.__file__).resolve().parents[1]
    try:
        commit = subprocess.run(["git", "-C", str(root), "rev-parse", "HEAD"], capture_output=True, text=True,
                                check=True).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(root), "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        commit, dirty = "unknown", ""
    return {"sofar_env": str(Path(module.__file__).resolve().parent), "commit": commit + ("+dirty" if dirty else "")}


def record_single(env_id: str, kwargs: dict[str, Any], episodes: int, steps: int) -> dict[str, np.ndarray]:
    import gymnasium as gym

    env = gym.make(env_id, reward_mode="vector", **kwargs)
    out: dict[str, np.ndarray] = {}
    for ep in range(episodes):
        obs, _ = env.reset(seed=1000 + ep, options={"rho": RHOS[ep % len(RHOS)]})
        o, r, d = [obs], [], []
        for t in range(steps):
            obs, rew, term, trunc, _ = env.step(np.array([gamma_schedule(t, ep)], np.float32))
            o.append(obs)
            r.append(np.atleast_1d(rew))
            d.append([term, trunc])
            if term or trunc:
                break
        out[f"ep{ep}|obs"], out[f"ep{ep}|reward"], out[f"ep{ep}|done"] = np.asarray(o), np.asarray(r), np.asarray(d)
    env.close()
    return out


def record_race(env_id: str, kwargs: dict[str, Any], cars: int, episodes: int, steps: int) -> dict[str, np.ndarray]:
    import gymnasium as gym

    from sofar_env.multi_agent import parallel_env

    race_kwargs = {**gym.spec(env_id).kwargs, **kwargs}
    track = race_kwargs.pop("track")
    env = parallel_env(track, n_agents=cars, reward_mode="vector", **race_kwargs)
    out: dict[str, np.ndarray] = {}
    for ep in range(episodes):
        env.reset(seed=2000 + ep)
        rows = []
        for t in range(steps):
            if not env.agents:
                break
            actions = {a: np.array([gamma_schedule(t, ep + k)], np.float32) for k, a in enumerate(env.agents)}
            obs, rew, term, trunc, _ = env.step(actions)
            rows += [np.concatenate([[t, k], obs[a], np.atleast_1d(rew[a]), [term[a], trunc[a]]])
                     for k, a in enumerate(sorted(obs))]
        out[f"ep{ep}|race"] = np.asarray(rows, float)
    env.close()
    return out


def record(args: argparse.Namespace) -> int:
    training = training_of(Path(args.checkpoint))
    kwargs = {**dict(training.get("env_kwargs") or {}), **parse_sets(args.set)}
    if training.get("decision_interval") is not None:
        kwargs["decision_interval"] = training["decision_interval"]
    import sofar_env  # registers the ids

    t0 = time.perf_counter()
    if training.get("multi_agent"):
        data = record_race(training["env_id"], kwargs, int(training["cars"]), args.episodes, args.steps)
    else:
        data = record_single(training["env_id"], kwargs, args.episodes, args.steps)
    meta = {"env_id": training["env_id"], "env_kwargs": kwargs, "multi_agent": bool(training.get("multi_agent")),
            "cars": training.get("cars"), "episodes": args.episodes, "steps": args.steps, **_code_of(sofar_env)}
    np.savez_compressed(args.out, meta=np.array(json.dumps(meta)), **data)
    logger.info("%d arrays of %s under %s (%s) in %.1f s -> %s", len(data), training["env_id"], meta["sofar_env"],
                meta["commit"], time.perf_counter() - t0, args.out)
    return 0


def backfill(args: argparse.Namespace) -> int:
    from sofar_agents.pasta.env_reconstruction import Replay, backfill_checkpoint, sidecar_path

    if len(args.evidence) % 2:
        raise SystemExit("--evidence takes pairs: THEN.npz NOW.npz ...")
    replays = [Replay.load(Path(then), Path(now)) for then, now in zip(args.evidence[::2], args.evidence[1::2])]
    side = backfill_checkpoint(Path(args.checkpoint), replays, args.unverified,
                               command=shlex.join(["python", "eval/training_env.py", *args.argv]), note=args.note)
    logger.info("%s: env_config_hash %s (%d of %d replays identical, %d stage(s) not replayable) -> %s",
                args.checkpoint, side.get("env_config_hash"), sum(r.identical for r in replays), len(replays),
                len(args.unverified), sidecar_path(Path(args.checkpoint)))
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    rec = sub.add_parser("record", help="replay seeded episodes of a checkpoint's training environment")
    rec.add_argument("--checkpoint", required=True, help="the checkpoint's JSON")
    rec.add_argument("--set", nargs="*", default=[], metavar="KEY=VALUE",
                     help="override or add environment keyword arguments (e.g. stack=sofar-1)")
    rec.add_argument("--out", required=True, help="output .npz")
    rec.add_argument("--episodes", type=count, default=3, help="seeded episodes (default 3)")
    rec.add_argument("--steps", type=count, default=300, help="decisions per episode at most (default 300)")
    fill = sub.add_parser("backfill", help="write the reconstructed record into the checkpoint")
    fill.add_argument("checkpoint")
    fill.add_argument("--evidence", nargs="+", required=True, metavar="NPZ",
                      help="pairs of recordings: under the training commit, under the current code with --set")
    fill.add_argument("--unverified", nargs="*", default=[], metavar="TEXT",
                      help="stages of a resumed run that no checkout can replay, and why")
    fill.add_argument("--note", default=None, help="kept with the record (e.g. where a difference was traced to)")
    args = parser.parse_args(argv)
    args.argv = list(sys.argv[1:] if argv is None else argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    return record(args) if args.command == "record" else backfill(args)


if __name__ == "__main__":
    sys.exit(main())
