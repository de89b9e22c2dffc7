"""Ray, imported lazily and started or joined in one place (sweeps and training).

``address=None`` starts a local Ray instance with a given number of CPUs;
``"auto"`` or ``"HOST:6379"`` joins a running cluster (``ray start --head``). Without
Ray installed, :func:`require_ray` raises an ImportError that says how to install it.
"""

from __future__ import annotations

import logging

INSTALL_HINT = 'the Ray backend needs Ray: pip install "sofar[ray]" (or, from a clone, pip install -e ".[ray]")'


def require_ray():
    """The ``ray`` module, or an ImportError saying how to install it."""
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
    ray = require_ray()
    if ray.is_initialized():
        return False
    if address is None:
        ray.init(num_cpus=int(num_cpus), include_dashboard=False, logging_level=logging.WARNING)
    else:
        ray.init(address=address, logging_level=logging.WARNING)
    return True
