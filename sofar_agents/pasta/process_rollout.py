"""PASTA rollouts in worker processes on this machine, with no barrier between the workers at each step.

:class:`ProcessEnvPool` is the :class:`~sofar_agents.pasta.actor_pool.ActorEnvPool` whose actors are
worker processes: each owns a slice of the envs and a copy of the policy, and steps them
``chunk_steps`` steps per call. A gymnasium ``AsyncVectorEnv`` instead waits for every worker at every
step, so each vector step lasts as long as the slowest worker's env step plus a round trip of messages;
here a worker goes on with its next step as soon as its own is done. A seeded run gives the same buffers,
updates and checkpoints as ``AsyncVectorEnv`` (and as the Ray backend) with the same ``n_envs``; why is in
:mod:`sofar_agents.pasta.actor_pool`. Needs no Ray.

Workers are started with the ``spawn`` method (no state inherited from the learner, whose torch threads
a forked child must not share; as with every spawned pool, the main script must be importable, so not
``python -`` reading standard input) and, with ``pin_workers``, each is pinned to a CPU of its own
(:func:`sofar_env.vector.worker_cpus`: Linux, and at least as many CPUs as workers). A worker that dies
or raises fails the rollout with ``RuntimeError`` naming it; the agent is left as it was.
"""

from __future__ import annotations

import multiprocessing as mp
import os
import signal
import traceback
from collections.abc import Callable, Sequence
from multiprocessing.connection import Connection, wait
from typing import Any

from sofar_agents.pasta.actor_pool import ActorEnvPool, EnvSlice
from sofar_env.vector import worker_cpus

__all__ = ["ProcessEnvPool"]

_JOIN_TIMEOUT_S = 5.0


def _describe_failure(exc: BaseException) -> str:
    """The exception on its first line, then the worker's traceback."""
    return "".join(traceback.format_exception_only(exc)).strip() + "\n\nin the worker:\n" + traceback.format_exc()


def _serve(conn: Connection, make_vector: Callable, start: int, n_total: int, cpu: int | None) -> None:
    """Worker process: build the :class:`EnvSlice`, then answer ``(method, args)`` calls until ``None`` arrives.

    Every answer is ``(True, value)`` or ``(False, the exception and its traceback)``; the construction is answered
    too.
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the learner's to handle: it then closes the pool
    if cpu is not None:
        os.sched_setaffinity(0, {cpu})
    try:
        actor = EnvSlice(make_vector, start, n_total)
    except Exception as exc:  # noqa: BLE001 (any failure is reported to the learner, which raises it)
        conn.send((False, _describe_failure(exc)))
        conn.close()
        return
    conn.send((True, None))
    while True:
        try:
            msg = conn.recv()
        except (EOFError, OSError):  # the learner is gone
            break
        if msg is None:
            break
        method, args = msg
        try:
            answer = (True, getattr(actor, method)(*args))
        except Exception as exc:  # noqa: BLE001 (any failure is reported to the learner, which raises it)
            answer = (False, _describe_failure(exc))
        conn.send(answer)
    actor.env.close()
    conn.close()


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
        ctx = mp.get_context("spawn")
        self._conns: list[Connection] = []
        self._procs: list[Any] = []
        try:
            for w, (lo, hi) in enumerate(self.slices):
                parent, child = ctx.Pipe()
                proc = ctx.Process(target=_serve, args=(child, self._vector_fns[w], lo, self.num_envs,
                                                        None if cpus is None else cpus[w]),
                                   name=f"sofar-rollout-{w}", daemon=True)
                proc.start()
                child.close()
                self._conns.append(parent)
                self._procs.append(proc)
            for w in range(len(self.slices)):
                self._get(w, w)  # the construction's answer
            self._describe()
        except BaseException:
            self.close()
            raise

    def _submit(self, w: int, method: str, *args: Any) -> int:
        try:
            self._conns[w].send((method, args))
        except OSError as err:  # a broken pipe: the worker is gone
            raise self._exited(w) from err
        return w

    def _wait_any(self, handles: list) -> int:
        conns = {self._conns[w]: w for w in handles}
        return conns[wait(list(conns))[0]]

    def _result(self, w: int, handle: int) -> Any:
        try:
            ok, value = self._conns[w].recv()
        except (EOFError, OSError) as err:
            raise self._exited(w) from err
        if not ok:
            raise RuntimeError(value)
        return value

    def _exited(self, w: int) -> RuntimeError:
        return RuntimeError(f"the process exited (exit code {self._procs[w].exitcode})")

    def close(self) -> None:
        """Stop the workers (those that do not stop within a few seconds are terminated)."""
        if self.closed:
            return
        self.closed = True
        for conn in self._conns:
            try:
                conn.send(None)
            except (OSError, ValueError):  # the worker is gone
                pass
        for proc in self._procs:
            proc.join(_JOIN_TIMEOUT_S)
            if proc.is_alive():
                proc.terminate()
                proc.join(_JOIN_TIMEOUT_S)
        for conn in self._conns:
            conn.close()

    def __del__(self) -> None:
        if not getattr(self, "closed", True):
            self.close()
