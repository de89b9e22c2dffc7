"""The worker body of the sweeps: :class:`EpisodeRunner` runs episode tasks with cached environments and policies.

A module of its own: the sweep (:mod:`~sofar_agents.evaluation.sweep`) hands the class to the executor
(:mod:`sofar_agents.executor`), whose backends build it in their workers and know nothing of episodes.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from sofar_agents.evaluation.episode import make_env, run_episode
from sofar_agents.evaluation.protocol import EpisodeTask, Strategy
from sofar_agents.evaluation.results import EpisodeResult

__all__ = ["EpisodeRunner"]


class EpisodeRunner:
    """Runs episode tasks in one process, building environments and policies on first use and keeping them
    (one environment per ``task.env_key``, one policy per strategy) until :meth:`close`.

    The worker body of every sweep backend: this process (one worker), the worker processes
    (:mod:`~sofar_agents.executor.processes`) and the Ray actors (:mod:`~sofar_agents.executor.ray_actors`).
    """

    def __init__(self) -> None:
        self.envs: dict[tuple, Any] = {}
        self.policies: dict[Strategy, Callable] = {}

    def run(self, task: EpisodeTask) -> tuple[EpisodeResult, list[tuple]]:
        """Run ``task``: its result and its trace rows (:func:`~sofar_agents.evaluation.episode.run_episode`)."""
        env, policy = self.env_and_policy(task)
        return run_episode(env, policy, task)

    def env_and_policy(self, task: EpisodeTask) -> tuple[Any, Callable]:
        """The environment and the policy of ``task``, built on first use and kept."""
        env = self.envs.get(task.env_key)
        if env is None:
            env = self.envs[task.env_key] = make_env(task.track, task.use_miqp, task.duration, task.stack,
                                                                     task.scenario)
        policy = self.policies.get(task.strategy)
        if policy is None:
            policy = self.policies[task.strategy] = task.strategy.build()
        return env, policy

    def close(self) -> None:
        """Close every environment built so far (errors while closing are ignored)."""
        for env in self.envs.values():
            try:
                env.close()
            except Exception:  # pragma: no cover
                pass
        self.envs.clear()
