"""Ray, imported lazily and started or joined in one place (sweeps and training).

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
"""

from __future__ import annotations

import logging
import os
import sys

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
