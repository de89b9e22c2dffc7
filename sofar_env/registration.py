"""Registration of the SOfAR environments with Gymnasium.

``import sofar_env`` registers one id per shipped circuit, e.g.
``gymnasium.make("SOfAR-LagunaSeca-v0")``, its interactive-world twin
``SOfAR-LagunaSeca-Interactive-v0``, the same world on the tyre model ``SOfAR-LagunaSeca-Dynamic-v0``, and :data:`CUSTOM_ID` for a circuit of your own::

    gymnasium.make("SOfAR-Custom-v0", track="path/to/MyCircuit")   # a folder of `python -m sofar_env.tracks build`
    gymnasium.make("SOfAR-Custom-v0", track=Track.load("path/to/MyCircuit"), scenario="interactive")

``gymnasium.make("sofar_env:SOfAR-Monza-v0")`` works without a prior import. The entry
points are ``"module:function"`` strings (:mod:`sofar_env.factory`), so the specs pickle
(vector environments) and nothing heavy is imported at registration; their vector entry points
(``gymnasium.make_vec``) give MO-Gymnasium's vector env in vector mode. The ids are registered
with ``disable_env_checker=True`` because the entry points apply Gymnasium's passive checker
themselves in scalar mode and leave it off in vector mode (see :mod:`sofar_env.factory`).

Version 1 of the two interactive worlds (``SOfAR-LagunaSeca-Interactive-v1``, ``SOfAR-LagunaSeca-Dynamic-v1``:
``scenario="interactive-2"`` and ``"dynamic-2"``) differs from version 0 in one rule of the opponent field: a squeezed
opponent drops back only for a car level with it, ahead of it or faster, so that a car standing behind it no longer
holds it at a standstill (the squeeze deadlock of version 0, :mod:`sofar_env.scenarios`). Version 0 stays registered
unchanged: its tables and the policies trained in it refer to it; ``gymnasium.make`` without a version takes the
latest.

The ids pass ``track=`` (and ``scenario=``) to the entry point; a ``config`` mapping that names another
track or world is refused (:func:`~sofar_env.config.make_env_config`), and ``track=`` / ``scenario=``
given to ``gymnasium.make`` replace the id's. The ids are registered without ``max_episode_steps``: an
environment truncates itself at its configured ``race.duration`` (any duration, time step and decision
interval), with ``info["is_success"]`` at its last step; a ``TimeLimit`` (``gymnasium.make(...,
max_episode_steps=N)``) would cut a longer race short.
"""

from __future__ import annotations

import gymnasium as gym

from .constants import CIRCUITS

__all__ = ["TRACKS", "ENV_IDS", "INTERACTIVE_IDS", "DYNAMIC_IDS", "INTERACTIVE_V1_IDS", "DYNAMIC_V1_IDS", "WORLD_IDS",
           "CUSTOM_ID", "MAX_EPISODE_STEPS", "register_envs"]

TRACKS = CIRCUITS
"""Circuits with a registered environment."""
ENV_IDS = tuple(f"SOfAR-{name}-v0" for name in TRACKS)
"""The paper-world ids, in the order of :data:`TRACKS`."""
INTERACTIVE_IDS = tuple(f"SOfAR-{name}-Interactive-v0" for name in TRACKS)
"""The interactive-world ids (``scenario="interactive"``, :mod:`sofar_env.scenarios`)."""
DYNAMIC_IDS = tuple(f"SOfAR-{name}-Dynamic-v0" for name in TRACKS)
"""The interactive world on the dynamic tyre plant (``scenario="dynamic"``)."""
INTERACTIVE_V1_IDS = tuple(f"SOfAR-{name}-Interactive-v1" for name in TRACKS)
"""Version 1 of the interactive world (``scenario="interactive-2"``: without the squeeze deadlock)."""
DYNAMIC_V1_IDS = tuple(f"SOfAR-{name}-Dynamic-v1" for name in TRACKS)
"""Version 1 of the dynamic world (``scenario="dynamic-2"``: without the squeeze deadlock)."""
WORLD_IDS: dict[str, tuple[str, ...]] = {"paper": ENV_IDS, "interactive": INTERACTIVE_IDS, "dynamic": DYNAMIC_IDS,
                                          "interactive-2": INTERACTIVE_V1_IDS, "dynamic-2": DYNAMIC_V1_IDS}
"""The registered ids of each world (``scenario``), in the order of :data:`TRACKS`."""
CUSTOM_ID = "SOfAR-Custom-v0"
"""A circuit of your own: ``track=`` a circuit folder or a :class:`~sofar_env.tracks.Track` (required; any world
through ``scenario=``)."""
MAX_EPISODE_STEPS = 2000
"""Control steps of the default race (200 s at dt = 0.1 s). Not a limit of the ids, which register none: each
environment ends its episode at its own ``race.duration``."""
ENTRY_POINT = "sofar_env.factory:make_env"
CUSTOM_ENTRY_POINT = "sofar_env.factory:make_custom_env"
VECTOR_ENTRY_POINT = "sofar_env.factory:make_vector_env"
"""What ``gymnasium.make_vec`` uses by default: MO-Gymnasium's ``MOSyncVectorEnv`` in vector mode
(:func:`sofar_env.factory.make_vector_env`)."""
CUSTOM_VECTOR_ENTRY_POINT = "sofar_env.factory:make_custom_vector_env"


def _register(env_id: str, entry_point: str, vector_entry_point: str, kwargs: dict) -> None:
    if env_id not in gym.registry:
        gym.register(id=env_id, entry_point=entry_point, vector_entry_point=vector_entry_point,
                     disable_env_checker=True, kwargs=kwargs)


def register_envs() -> None:
    """Register every id of :data:`ENV_IDS`, :data:`INTERACTIVE_IDS`, :data:`DYNAMIC_IDS`, :data:`INTERACTIVE_V1_IDS`,
    :data:`DYNAMIC_V1_IDS` and :data:`CUSTOM_ID` (idempotent)."""
    for world, ids in WORLD_IDS.items():
        extra = {} if world == "paper" else {"scenario": world}
        for name, env_id in zip(TRACKS, ids):
            _register(env_id, ENTRY_POINT, VECTOR_ENTRY_POINT, {"track": name, **extra})
    _register(CUSTOM_ID, CUSTOM_ENTRY_POINT, CUSTOM_VECTOR_ENTRY_POINT, {})
