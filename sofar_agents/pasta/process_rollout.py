"""PASTA rollouts in worker processes on this machine, with no barrier between the workers at each step.

:class:`ProcessEnvPool` is the :class:`~sofar_agents.pasta.actor_pool.ActorEnvPool` whose actors are
worker processes: each owns a slice of the envs and a copy of the policy, and steps them
``chunk_steps`` steps per call. A gymnasium ``AsyncVectorEnv`` instead waits for every worker at every
step, so each vector step lasts as long as the slowest worker's env step plus a round trip of messages;
here a worker goes on with its next step as soon as its own is done. A seeded run gives the same buffers,
updates and checkpoints as ``AsyncVectorEnv`` (and as the Ray backend) with the same ``n_envs``; why is in
:mod:`sofar_agents.pasta.actor_pool`. Needs no Ray.

Workers are :class:`~sofar_agents.worker_processes.WorkerProcess` es, the transport of every process pool of the
package (the executor's too): started with the ``spawn`` method (no state inherited from the learner, whose torch
threads a forked child must not share; as with every spawned pool, the main script must be importable, so not
``python -`` reading standard input), tied to the learner (they end with it, even when it is killed with SIGKILL;
they ignore Ctrl-C, which is the learner's) and, with ``pin_workers``, each pinned to a CPU of its own
(:func:`sofar_env.vector.worker_cpus`: Linux, and at least as many CPUs as workers). A worker that dies
or raises fails the rollout with ``RuntimeError`` naming it; the agent is left as it was. Why the training pools
share the transport but not the executor's task queue: docs/decisions/one-executor.md.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Sequence
from typing import Any

from sofar_agents.pasta.actor_pool import ActorEnvPool, EnvSlice
from sofar_agents.worker_processes import WorkerProcess, stop_workers, wait_ready
from sofar_env.vector import worker_cpus

__all__ = ["ProcessEnvPool"]

_JOIN_TIMEOUT_S = 5.0


class _ProcessSlice(EnvSlice):
    """The worker body: an :class:`EnvSlice` whose envs are closed when the worker stops."""

    def close(self) -> None:
        self.env.close()


class ProcessEnvPool(ActorEnvPool):
    """``n_envs`` training envs in ``num_workers`` worker processes, used by :meth:`PASTA.learn` like a vector env.

    Args:
        env_fns: one picklable zero-argument env factory per env (e.g.
            ``functools.partial(make_training_env, ...)``); env i is seeded like env i of
            a local vector env.
        num_workers: worker processes; the envs are split into contiguous slices.
        chunk_steps: steps a worker runs per call (the waits for preference draws are at
            most one chunk long); it does not change the result.
        pin_workers: pin worker w to the w-th CPU of this process's affinity set (only where
            :func:`sofar_env.vector.worker_cpus` allows it); it does not change the result.
        cars_per_race: ``env_fns`` build PettingZoo races of this many cars (self-play; every car is a slot,
            as in :class:`~sofar_agents.pasta.self_play.RaceVectorEnv`); None: they build gymnasium envs.

    Raises:
        ValueError: ``num_workers`` outside ``[1, len(env_fns)]``, ``chunk_steps < 1`` or ``cars_per_race < 1``.
        RuntimeError: a worker failed to build its envs (the message holds its traceback).
    """

    worker_label = "rollout worker process"

    def __init__(self, env_fns: Sequence[Callable[[], Any]], num_workers: int, chunk_steps: int = 64,
                 pin_workers: bool = True, cars_per_race: int | None = None) -> None:
        super().__init__(env_fns, num_workers, chunk_steps, cars_per_race)
        cpus = worker_cpus(len(self.slices)) if pin_workers else None
        self.pinned = cpus is not None
        """Whether each worker runs on a CPU of its own."""
        self._workers: list[WorkerProcess] = []
        try:
            for w, (lo, _) in enumerate(self.slices):
                body = functools.partial(_ProcessSlice, self._vector_fns[w], lo, self.num_envs)
                self._workers.append(WorkerProcess(body, name=f"sofar-rollout-{w}", announce=True,
                                                   cpu=None if cpus is None else cpus[w]))
            for w in range(len(self.slices)):
                self._get(w, w)  # the construction's answer
            self._describe()
        except BaseException:
            self.close()
            raise

    @property
    def _procs(self) -> list:
        """The worker processes (``multiprocessing.Process``), in worker order."""
        return [w.process for w in self._workers]

    def _submit(self, w: int, method: str, *args: Any) -> int:
        self._workers[w].call(method, *args)  # WorkerGone (a RuntimeError) names the exit code
        return w

    def _wait_any(self, handles: list) -> int:
        index = {id(self._workers[w]): w for w in handles}
        return index[id(wait_ready([self._workers[w] for w in handles])[0])]

    def _result(self, w: int, handle: int) -> Any:
        return self._workers[w].answer()

    def close(self) -> None:
        """Stop the workers (those that do not stop within a few seconds are killed)."""
        if self.closed:
            return
        self.closed = True
        stop_workers(self._workers, _JOIN_TIMEOUT_S)

    def __del__(self) -> None:
        if not getattr(self, "closed", True):
            self.close()
