"""Ray, imported lazily and started or joined in one place (sweeps and training), and actors tied to their driver.

``address=None`` starts a local Ray instance with a given number of CPUs;
``"auto"`` or ``"HOST:6379"`` joins a running cluster (``ray start --head``). Without
Ray installed, :func:`require_ray` raises an ImportError that says how to install it.

A private local instance runs with Ray's token authentication, which Ray turns on by default
for new local clusters with a warning that it did so: ``require_ray(local=True)`` sets
``RAY_AUTH_MODE=token`` before Ray is imported (unless the variable is set already), which is
the same mode, chosen explicitly, so Ray has nothing to warn about. Joining a cluster leaves
the variable to the user (the cluster's nodes decide the mode).

Start-up: a local instance takes a few seconds to start and each worker imports the package
and builds its environments once, so Ray is slower than the default process pool on small
sweeps such as ``eval/table.py --quick`` or ``train/pasta.py --quick`` (where the start-up is
most of the run); it pays off on long sweeps, and on a cluster.

Actors tied to the driver: Ray ends a job's actors once it notices that their driver has exited. As a guard that
does not depend on Ray noticing, every actor of the package (the executor's and the training pool's) takes the
driver's :func:`driver_identity` and calls :func:`follow_driver` first thing: an actor on the driver's machine
then ends its own process as soon as the driver's process has ended
(:func:`~sofar_agents.worker_lifetime.exit_with_process`), also when the driver was killed with SIGKILL.
"""

from __future__ import annotations

import logging
import os
import sys

from sofar_agents.worker_lifetime import exit_with_process, process_start_time

__all__ = ["INSTALL_HINT", "DriverIdentity", "driver_identity", "follow_driver", "init_ray", "require_ray"]

DriverIdentity = tuple[str, int, "str | None"]
"""``(Ray node id, pid, process start time)`` of a driver (:func:`driver_identity`)."""

INSTALL_HINT = 'the Ray backend needs Ray: pip install "sofar[ray]" (or, from a clone, pip install -e ".[ray]")'


def require_ray(local: bool = False):
    """The ``ray`` module, or an ImportError saying how to install it.

    ``local``: this process will start a private local Ray instance; its token authentication is
    chosen explicitly (``RAY_AUTH_MODE=token`` unless set) when Ray is not imported yet (module docstring).
    """
    if local and "ray" not in sys.modules:
        os.environ.setdefault("RAY_AUTH_MODE", "token")
    try:
        import ray
    except ImportError as exc:
        raise ImportError(INSTALL_HINT) from exc
    return ray


def init_ray(address: str | None, num_cpus: int) -> bool:
    """Start a local Ray instance with ``num_cpus`` CPUs (``address=None``) or join ``address``.

    Does nothing when Ray is already initialised. Returns whether this call started it
    (the caller then shuts it down).
    """
    ray = require_ray(local=address is None)
    if ray.is_initialized():
        return False
    if address is None:
        ray.init(num_cpus=int(num_cpus), include_dashboard=False, logging_level=logging.WARNING)
    else:
        ray.init(address=address, logging_level=logging.WARNING)
    return True


def driver_identity() -> DriverIdentity:
    """This process's :data:`DriverIdentity`, for its actors' :func:`follow_driver` (Ray must be initialised)."""
    ray = require_ray()
    return ray.get_runtime_context().get_node_id(), os.getpid(), process_start_time(os.getpid())


def follow_driver(driver: DriverIdentity | None) -> None:
    """In an actor: end this process once the driver ``driver`` has ended, if it runs on this node.

    None, or a driver on another node, does nothing (Ray ends those actors when the driver's job ends).
    """
    if driver is None:
        return
    import ray

    node_id, pid, start_time = driver
    if ray.get_runtime_context().get_node_id() == node_id:
        exit_with_process(pid, start_time)
