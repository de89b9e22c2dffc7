"""Vector envs of SOfAR worlds: gymnasium's ``AsyncVectorEnv`` with each worker on a CPU of its own.

Why pin the workers
-------------------
An ``AsyncVectorEnv`` steps in lock-step: the main process sends every worker its action, waits for all
of them, merges their answers and only then sends the next actions. Between two steps every worker is
idle, and the operating system is free to wake it on another CPU than the one it ran on, away from its
caches; it also has to find an idle CPU for it first, while the main process is still running. Pinning
worker ``i`` to CPU ``i`` (``os.sched_setaffinity``) removes both. On a 2-core virtual machine,
``bench/bench_vector.py`` measured, for two workers running ``SOfAR-LagunaSeca-v0`` (10 rounds, medians),
that the time from the main process's ``step`` call to the start of the worker waited for falls from 0.38
to 0.17 ms, and the vector env's throughput rises by 1.23x (per round 1.01x to 1.33x; in
``bench/bench_env.py --vector``, whose passes run in separate processes, the gain was within the noise).
Pinning changes where the workers run, never what they compute: seeded results are the same.

A worker is pinned only where the platform can (Linux: ``os.sched_setaffinity``) and only when there are
at least as many CPUs available to this process as workers; otherwise the workers are left to the
operating system, as without this module. The main process is never pinned: gymnasium builds one env in
it to read the spaces, and the factories below leave that one alone. The price: a pinned worker cannot
move away from a CPU that another program keeps busy; on a machine shared with other heavy jobs, pass
``pin_workers=False`` (``--no-pin-workers`` of the training scripts).
"""

from __future__ import annotations

import logging
import os
from collections.abc import Callable, Sequence
from typing import Any

import gymnasium as gym

__all__ = ["PinnedFactory", "async_vector_env", "available_cpus", "pinned_factories", "worker_cpus"]

logger = logging.getLogger(__name__)


def available_cpus() -> int:
    """How many CPUs this process may run on: its affinity set where the platform tells it, else the CPU count."""
    if hasattr(os, "sched_getaffinity"):
        return len(os.sched_getaffinity(0))
    return os.cpu_count() or 1


def worker_cpus(n_workers: int) -> list[int] | None:
    """The CPU for each of ``n_workers`` workers: the first ``n_workers`` of the CPUs this process may run on,
    or None when the platform cannot pin or there are fewer CPUs than workers."""
    if n_workers < 1:
        raise ValueError(f"n_workers must be >= 1, got {n_workers}")
    if not (hasattr(os, "sched_getaffinity") and hasattr(os, "sched_setaffinity")):
        return None
    cpus = sorted(os.sched_getaffinity(0))
    if n_workers > len(cpus):
        return None
    return cpus[:n_workers]


class PinnedFactory:
    """An env factory that, when called in a process other than the one that made it, first pins that
    process to ``cpu``. Picklable when ``env_fn`` is (as ``AsyncVectorEnv`` needs)."""

    def __init__(self, env_fn: Callable[[], gym.Env], cpu: int):
        if not callable(env_fn):
            raise TypeError(f"env_fn must be callable, got {type(env_fn).__name__}")
        self.env_fn = env_fn
        self.cpu = int(cpu)
        self.parent_pid = os.getpid()

    def __call__(self) -> gym.Env:
        if os.getpid() != self.parent_pid:  # a worker: pin it (the parent builds one env only to read the spaces)
            os.sched_setaffinity(0, {self.cpu})
            logger.debug("vector env worker %d pinned to CPU %d", os.getpid(), self.cpu)
        return self.env_fn()


def pinned_factories(env_fns: Sequence[Callable[[], gym.Env]], pin: bool = True) -> list[Callable[[], gym.Env]]:
    """``env_fns`` with factory ``i`` pinning its worker to the ``i``-th CPU (:func:`worker_cpus`); unchanged when
    ``pin`` is False or pinning is not possible here."""
    fns = list(env_fns)
    if not fns:
        raise ValueError("env_fns is empty")
    cpus = worker_cpus(len(fns)) if pin else None
    if cpus is None:
        return fns
    return [PinnedFactory(fn, cpu) for fn, cpu in zip(fns, cpus)]


def async_vector_env(env_fns: Sequence[Callable[[], gym.Env]], *, pin_workers: bool = True,
                     **kwargs: Any) -> gym.vector.AsyncVectorEnv:
    """A gymnasium ``AsyncVectorEnv`` of ``env_fns`` whose workers are pinned to a CPU each (module docstring);
    ``kwargs`` go to ``AsyncVectorEnv``."""
    return gym.vector.AsyncVectorEnv(pinned_factories(env_fns, pin_workers), **kwargs)
