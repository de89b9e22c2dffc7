"""SOfAR agents: PASTA (multi-objective PPO for the barrier decay gamma) and policies.

Attributes are imported lazily so that ``import sofar_agents`` does not import torch.
"""

from __future__ import annotations

import importlib
from typing import Any

__version__ = "0.1.0"

__all__ = [
    "PASTA",
    "PASTAConfig",
    "compute_gae",
    "load_policy",
    "default_policy_path",
    "named_policy_path",
    "FixedGammaPolicy",
    "SB3Policy",
]

_LAZY = {
    "PASTA": "sofar_agents.pasta",
    "PASTAConfig": "sofar_agents.pasta",
    "compute_gae": "sofar_agents.pasta",
    "load_policy": "sofar_agents.policies",
    "default_policy_path": "sofar_agents.policies",
    "named_policy_path": "sofar_agents.policies",
    "FixedGammaPolicy": "sofar_agents.policies",
    "SB3Policy": "sofar_agents.policies",
}


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'sofar_agents' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(list(globals()) + __all__)
