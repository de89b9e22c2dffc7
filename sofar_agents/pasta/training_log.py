"""Console, TensorBoard and run-directory helpers of the PASTA training script.

Kept out of ``train/pasta.py`` so the script stays a thin command line: the
per-update TensorBoard scalars (losses, attention, regret and returns per objective,
by name), the one console line per update, the objective names and count of a vector
env, the refusal to write into another run's folder, and the git commit of the source tree.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from sofar_agents.pasta.agent import PASTA


def objective_names(vec_env: gym.vector.VectorEnv) -> tuple[str, ...] | None:
    """The objective names the env declares (``objective_names``), or None."""
    try:
        names = vec_env.get_attr("objective_names")[0]
        return tuple(str(n) for n in names)
    except (AttributeError, IndexError, TypeError):
        return None


def n_objectives(vec_env: gym.vector.VectorEnv) -> int:
    """The number of objectives, from the env's ``reward_space``."""
    try:
        space = vec_env.get_attr("reward_space")[0]
        return int(np.prod(space.shape))
    except (AttributeError, IndexError, TypeError) as err:
        raise SystemExit("the environment must declare env.unwrapped.reward_space") from err


def log_update(writer: Any, agent: PASTA, stats: dict[str, Any]) -> None:
    """Write one update's statistics to a TensorBoard ``SummaryWriter``, per objective by name."""
    step = agent.num_timesteps
    names = agent.objective_names
    for key in ("policy_loss", "value_loss", "entropy", "approx_kl", "clipfrac", "log_std"):
        writer.add_scalar(f"losses/{key}", stats[key], step)
    writer.add_scalar("pasta/mu", stats["mu"], step)
    writer.add_scalar("pasta/conflict_ratio", stats["conflict_ratio"], step)
    writer.add_scalar("charts/sps", stats["sps"], step)
    if "collect_time" in stats:  # where the time goes: env steps (collection) or the learner (update)
        n_collected = stats["rollout"].rewards.shape[0] * stats["rollout"].rewards.shape[1]
        writer.add_scalar("charts/collect_sps", n_collected / max(stats["collect_time"], 1e-9), step)
        writer.add_scalar("time/collect_s", stats["collect_time"], step)
    writer.add_scalar("time/update_s", stats["update_time"], step)
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


def format_number(value: float, digits: int = 3) -> str:
    """``value`` with ``digits`` decimals, without the sign of a value that rounds to zero (no ``-0.000``)."""
    text = f"{float(value):.{digits}f}"
    return text[1:] if text.startswith("-") and float(text) == 0.0 else text


def format_returns(names: tuple[str, ...], returns: np.ndarray) -> str:
    """``safety -0.120  overtakes 1.000 ...``: per-objective returns labelled with the objective names."""
    return "  ".join(f"{name} {format_number(value)}" for name, value in zip(names, returns))


def console_line(agent: PASTA, stats: dict[str, Any], total_steps: int) -> str:
    """One line per update: progress, finished episodes and their mean returns per objective (by name)."""
    recent = list(agent.ep_info_buffer)
    line = (f"update {agent.num_updates}  steps {agent.num_timesteps}/{total_steps}  "
            f"episodes +{len(stats['episodes'])}")
    if recent:
        returns = np.mean([e["returns"] for e in recent], axis=0)
        line += f"  mean returns of the last {len(recent)}: " + format_returns(agent.objective_names, returns)
    else:
        line += "  (no episode finished yet)"
    line += f"  mu {stats['mu']:.2f}  conflict {stats['conflict_ratio']:.2f}  sps {stats['sps']:.0f}"
    if "collect_time" in stats:
        line += f" (collection {stats['collect_time']:.1f} s, update {stats['update_time']:.1f} s)"
    return line


def run_folder(checkpoint: str | Path) -> Path:
    """The run folder of a checkpoint: the folder of ``pasta_final``, or the one above ``checkpoints/``."""
    parent = Path(checkpoint).resolve().parent
    return parent.parent if parent.name == "checkpoints" else parent


def check_out(out: Path, force: bool, resume: str | Path | None = None) -> None:
    """Refuse an ``--out`` that already holds a run, unless ``force`` (start over there) or ``resume`` is a
    checkpoint of that run (continue it in its own folder, the normal case of ``--resume``)."""
    final = out / "pasta_final.json"
    if not final.exists() or force:
        return
    if resume is not None and run_folder(resume) == out.resolve():
        return
    try:
        steps = f", {int(json.loads(final.read_text())['state']['num_timesteps'])} steps"
    except (OSError, ValueError, KeyError, TypeError):
        steps = ""
    raise SystemExit(f"--out {out} already holds a run ({final}{steps}): continue it with --resume {final}, "
                     "start over there with --force (its checkpoints are replaced), or choose another --out")


def code_commit(root: Path) -> str | None:
    """The git commit of the source tree at ``root`` (``+dirty`` if modified), if known."""
    import subprocess

    try:
        commit = subprocess.run(["git", "-C", str(root), "rev-parse", "HEAD"], capture_output=True, text=True,
                                timeout=5, check=True).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(root), "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True, timeout=5, check=True).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return None
    return commit + ("+dirty" if dirty else "")
