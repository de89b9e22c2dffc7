"""One evaluation episode: build the environment, run a policy to the horizon, record the result."""

from __future__ import annotations

import math
import time
import warnings
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from sofar_agents.evaluation.protocol import DEFAULT_DURATION, EpisodeTask, _fmt_float
from sofar_agents.evaluation.results import EpisodeResult

_SLACK_TOL = 1e-4
"""DCBF slack above this counts as barrier-slack activity [units of h]."""


def _info_scalar(info: Mapping[str, Any], key: str, default: float = 0.0) -> float:
    v = info.get(key, default)
    try:
        v = float(np.asarray(v, dtype=float).reshape(-1)[0]) if np.ndim(v) else float(v)
    except (TypeError, ValueError, IndexError):
        return float(default)
    return v


def slack_active(info: Mapping[str, Any]) -> bool:
    """Whether the MPC used DCBF slack in this step, from the step's ``info``.

    Uses ``info["barrier_slack"]`` when the environment reports it; otherwise the safety
    cost (barrier slack + 1 per collision + 1 per leaving the track) minus the events.
    """
    if "barrier_slack" in info:
        return _info_scalar(info, "barrier_slack") > _SLACK_TOL
    if "cost" in info:
        events = float(bool(info.get("collision", False))) + float(bool(info.get("off_track", False)))
        return _info_scalar(info, "cost") - events > _SLACK_TOL
    return False


def run_episode(env, policy: Callable[[Any], Any], task: EpisodeTask) -> tuple[EpisodeResult, list[tuple]]:
    """Run one episode of ``task`` in ``env`` (already built for its track/MIQP setting).

    Returns the result and, when ``task.trace``, the per-step rows of :data:`TRACE_COLUMNS`.
    The episode ends at a termination (collision, leaving the track, stalling), at the environment's
    truncation, or once the simulated time reaches ``task.duration``. The result's ``config_hash`` is that of
    ``env``'s configuration; a task with a hash (:attr:`EpisodeTask.config_hash`) in an environment of another
    configuration raises ``RuntimeError`` before the reset (its row would name a configuration it did not run).
    """
    env_hash = _env_config_hash(env)
    wanted = getattr(task, "config_hash", None)
    if wanted and env_hash != wanted:
        raise RuntimeError(f"episode {task.track}/{task.strategy.name}: the environment's configuration has "
                           f"config_hash {env_hash}, the task's is {wanted} (stack {task.stack!r}, scenario "
                           f"{task.scenario!r}, duration {task.duration:g} s)")
    t0 = time.perf_counter()
    obs, info = env.reset(seed=int(task.seed), options=reset_options(task))
    steps = slack = 0
    gamma_sum = 0.0
    collision = off_track = stalled = terminated = truncated = False
    trace: list[tuple] = []
    while True:
        action = np.asarray(policy(obs), dtype=np.float32).reshape(1)
        obs, _, terminated, truncated, info = env.step(action)
        steps += 1
        gamma = _info_scalar(info, "gamma", float(action[0]))
        gamma_sum += gamma
        slack += int(slack_active(info))
        collision |= bool(info.get("collision", False))
        off_track |= bool(info.get("off_track", False))
        stalled |= bool(info.get("stalled", False))
        sim_time = _info_scalar(info, "sim_time", math.nan)
        if task.trace:
            trace.append((task.track, task.strategy.name, _fmt_float(task.rho), task.seed, steps, sim_time, gamma,
                          _info_scalar(info, "nearest_opponent_m", math.nan),
                          _info_scalar(info, "min_barrier", math.nan)))
        if terminated or truncated or sim_time >= task.duration - 1e-6:
            break
    if "is_success" in info and (terminated or truncated):
        success = bool(info["is_success"])
    else:  # stopped at our own horizon
        success = not (terminated or collision or off_track or stalled)
    if success and sim_time < task.duration - 1e-6:
        warnings.warn(f"the environment ended the episode at {sim_time:.1f} s, before the {task.duration:g} s "
                      "horizon", stacklevel=2)
    result = EpisodeResult(
        track=task.track, strategy=task.strategy.name, rho=float(task.rho), seed=int(task.seed), success=success,
        sim_time=float(sim_time), laps=_info_scalar(info, "laps"), overtakes=int(_info_scalar(info, "overtakes")),
        collision=collision, off_track=off_track, slack_steps=slack, steps=steps,
        mean_gamma=gamma_sum / max(steps, 1), mpc_failures=int(_info_scalar(info, "mpc_failures")),
        miqp_failures=int(_info_scalar(info, "miqp_failures")), wall_time=time.perf_counter() - t0,
        episode=int(task.episode), use_miqp=bool(task.use_miqp), duration=float(task.duration),
        policy_id=task.strategy.policy_id, stack=task.stack, scenario=task.scenario,
        n_opponents="" if task.n_opponents is None else int(task.n_opponents), stalled=stalled,
        config_hash=env_hash,
    )
    return result, trace


def reset_options(task: EpisodeTask) -> dict[str, Any]:
    """The ``options`` of ``env.reset`` for ``task``: its rho, and its field size when it sets one."""
    options: dict[str, Any] = {"rho": float(task.rho)}
    if task.n_opponents is not None:
        options["n_opponents"] = int(task.n_opponents)
    return options


def make_env(track: str, use_miqp: bool = True, duration: float = DEFAULT_DURATION, stack: str = "sofar",
             scenario: str = "paper",
             **kwargs):
    """``gymnasium.make("SOfAR-<track>-v0")`` with the MIQP setting, the controller preset and the horizon."""
    import gymnasium as gym

    import sofar_env  # noqa: F401  (registers the environments)

    from sofar_env.race import RaceConfig

    from sofar_agents.evaluation.configs import episode_env_mapping

    # the registered ids cap episodes at 2000 steps (200 s); follow the requested horizon instead
    steps = int(math.ceil(float(duration) / RaceConfig().dt - 1e-9)) + 1
    return gym.make(f"SOfAR-{track}-v0", max_episode_steps=steps, use_miqp=bool(use_miqp),
                    config=episode_env_mapping(duration, stack, scenario), **kwargs)


def _env_config_hash(env) -> str:
    """The configuration hash of ``env`` (wrapped or not)."""
    from sofar_env.config_hash import config_hash

    return config_hash(env.unwrapped.config)
