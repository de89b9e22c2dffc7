"""Registration of the SOfAR environments with Gymnasium.

``import sofar_env`` registers one id per shipped circuit, e.g.
``gymnasium.make("SOfAR-LagunaSeca-v0")``; ``gymnasium.make("sofar_env:SOfAR-Monza-v0")``
works without a prior import. The entry point is a ``"module:Class"`` string, so the
specs pickle (vector environments) and nothing heavy is imported at registration.
"""

from __future__ import annotations

import gymnasium as gym

from .constants import CIRCUITS

__all__ = ["TRACKS", "ENV_IDS", "INTERACTIVE_IDS", "MAX_EPISODE_STEPS", "register_envs"]

TRACKS = CIRCUITS
"""Circuits with a registered environment."""
ENV_IDS = tuple(f"SOfAR-{name}-v0" for name in TRACKS)
"""The paper-world ids, in the order of :data:`TRACKS`."""
INTERACTIVE_IDS = tuple(f"SOfAR-{name}-Interactive-v0" for name in TRACKS)
"""The interactive-world ids (``scenario="interactive"``, :mod:`sofar_env.scenarios`)."""
MAX_EPISODE_STEPS = 2000
"""200 s at dt = 0.1 s."""
ENTRY_POINT = "sofar_env.env:SOfARRaceEnv"


def register_envs() -> None:
    """Register every id of :data:`ENV_IDS` and :data:`INTERACTIVE_IDS` (idempotent)."""
    for ids, extra in ((ENV_IDS, {}), (INTERACTIVE_IDS, {"scenario": "interactive"})):
        for name, env_id in zip(TRACKS, ids):
            if env_id in gym.registry:
                continue
            gym.register(
                id=env_id,
                entry_point=ENTRY_POINT,
                max_episode_steps=MAX_EPISODE_STEPS,
                kwargs={"track": name, **extra},
            )
