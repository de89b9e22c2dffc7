"""Entry points of the registered ids: the Gymnasium environment, passive-checked in scalar mode.

The ids of :mod:`sofar_env.registration` are registered with ``disable_env_checker=True``
and point here, so that the passive checker follows the reward mode:

* ``reward_mode="scalar"`` (default): the environment is wrapped in Gymnasium's
  :class:`~gymnasium.wrappers.PassiveEnvChecker`, exactly where ``gymnasium.make`` puts it
  for any other id (``OrderEnforcing<PassiveEnvChecker<SOfARRaceEnv>>``; the ids add no ``TimeLimit``: the
  environment truncates itself at its configured race duration);
* ``reward_mode="vector"``: no checker. The step returns the float32 reward vector of
  ``env.unwrapped.reward_space`` (the MO-Gymnasium convention), which the checker, written for
  scalar rewards, reports as "must be a float". ``mo_gymnasium.make`` turns the checker off for
  the same reason; with these entry points ``gymnasium.make(id, reward_mode="vector")`` behaves
  the same.

Because the checker is applied here, ``gymnasium.make(..., disable_env_checker=...)`` does not
change it; ``disable_env_checker=False`` adds Gymnasium's own checker on top (harmless, and it
warns about the vector reward as requested).

:func:`make_custom_env` is the entry point of ``SOfAR-Custom-v0``: a circuit of your own,
given as ``track=`` a circuit folder (written by ``python -m sofar_env.tracks build``) or a
:class:`~sofar_env.tracks.Track`.

:func:`make_vector_env` and :func:`make_custom_vector_env` are the ids' vector entry points, which
``gymnasium.make_vec(id, num_envs, **kwargs)`` uses by default: ``num_envs`` environments made with
``gymnasium.make(id, **kwargs)`` in a ``gymnasium.vector.SyncVectorEnv`` in scalar mode, and in
MO-Gymnasium's ``MOSyncVectorEnv`` with ``reward_mode="vector"`` (a ``(num_envs, 5)`` reward array;
Gymnasium's ``SyncVectorEnv`` stores one float per env and cannot hold the vector). As for every id with a
vector entry point, ``make_vec``'s ``wrappers=`` and ``vector_kwargs=`` need ``vectorization_mode="sync"``
or ``"async"``, which build Gymnasium's vector envs: scalar rewards only.
"""

from __future__ import annotations

import functools
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import gymnasium as gym

from .env import SOfARRaceEnv
from .registration import CUSTOM_ID, ENV_IDS, WORLD_IDS
from .tracks import Track

__all__ = ["make_env", "make_custom_env", "make_vector_env", "make_custom_vector_env", "load_custom_track"]


_BUILD_HINT = ("build one with `python -m sofar_env.tracks build EDGES.csv --name NAME --out DIR` "
               "(or pass a sofar_env.tracks.Track); the shipped circuits have their own ids, SOfAR-<Circuit>-v0")


class _PassiveEnvChecker(gym.wrappers.PassiveEnvChecker):
    """Gymnasium's passive checker, applied by the entry point: the spec keeps ``disable_env_checker=True``.

    (Gymnasium's wrapper sets it to False in the spec, so ``gymnasium.make(env.spec)`` would add a second one.)

    A ``reset()`` or ``step()`` that raises leaves the checker as it was, so its first-call checks run on the
    first call that succeeds. (Gymnasium's own marks the reset as checked before calling it; after a first
    reset that raised, every later step raised a ``TypeError`` from its data-reuse check.)
    """

    @property
    def spec(self):
        return self.env.spec

    def reset(self, *, seed=None, options=None):
        if self.checked_reset:
            return self.env.reset(seed=seed, options=options)
        saved = dict(vars(self))
        try:
            return super().reset(seed=seed, options=options)
        except BaseException:
            vars(self).clear()
            vars(self).update(saved)
            raise

    def step(self, action):
        if self.checked_step and getattr(self, "checked_data_reuse", True):
            return self.env.step(action)
        saved = dict(vars(self))
        try:
            return super().step(action)
        except BaseException:
            vars(self).clear()
            vars(self).update(saved)
            raise


def make_env(**kwargs: Any) -> gym.Env:
    """A :class:`~sofar_env.env.SOfARRaceEnv` from ``kwargs``, passive-checked unless ``reward_mode="vector"``."""
    env = SOfARRaceEnv(**kwargs)
    if env.config.reward_mode == "vector":
        return env
    return _PassiveEnvChecker(env)


make_env.metadata = SOfARRaceEnv.metadata  # read by gymnasium.make (render-mode wrappers)



def load_custom_track(track: Any) -> Track:
    """The :class:`~sofar_env.tracks.Track` of ``SOfAR-Custom-v0`` from a folder path or a Track.

    Raises ``ValueError`` when ``track`` is missing (None), of the wrong type or not a folder, and
    :class:`~sofar_env.tracks.TrackFormatError` (a ``ValueError`` naming the file) for a malformed folder.
    """
    if isinstance(track, Track):
        return track
    if track is None:
        raise ValueError(f"{CUSTOM_ID} needs track=<circuit folder or Track>; {_BUILD_HINT}")
    if not isinstance(track, (str, os.PathLike)):
        raise ValueError(f"{CUSTOM_ID}: track must be a circuit folder path or a Track, got {type(track).__name__}")
    folder = Path(track).expanduser()
    if not folder.is_dir():
        raise ValueError(f"{CUSTOM_ID}: track {os.fspath(track)!r} is not a circuit folder; {_BUILD_HINT}")
    return Track.load(folder)


def make_custom_env(track: Any = None, **kwargs: Any) -> gym.Env:
    """Entry point of ``SOfAR-Custom-v0``: :func:`make_env` on the circuit ``track`` (see :func:`load_custom_track`).

    The circuit is loaded (and checked) here, when the environment is made; ``track`` may also be given as
    ``config={"track": ...}``.
    """
    config = kwargs.get("config")
    if track is None and isinstance(config, Mapping) and "track" in config:
        config = dict(config)
        track = config.pop("track")
        kwargs["config"] = config
    return make_env(track=load_custom_track(track), **kwargs)


make_custom_env.metadata = SOfARRaceEnv.metadata


def make_vector_env(num_envs: int = 1, **kwargs: Any) -> gym.vector.VectorEnv:
    """Vector entry point of the ``SOfAR-<Circuit>-...`` ids: ``num_envs`` x ``gymnasium.make(id, **kwargs)`` in a
    ``SyncVectorEnv``, or in MO-Gymnasium's ``MOSyncVectorEnv`` with ``reward_mode="vector"``.

    ``kwargs`` are the id's (``track``, ``scenario``) with the caller's on top and ``max_episode_steps``, as
    ``gymnasium.make_vec`` passes them; they make the environments (the id only names their specs).
    """
    return _vector_env(_circuit_id(kwargs), num_envs, kwargs)


def make_custom_vector_env(num_envs: int = 1, **kwargs: Any) -> gym.vector.VectorEnv:
    """Vector entry point of ``SOfAR-Custom-v0``: as :func:`make_vector_env`, on the circuit ``track``."""
    return _vector_env(CUSTOM_ID, num_envs, kwargs)


def _vector_env(env_id: str, num_envs: int, kwargs: dict[str, Any]) -> gym.vector.VectorEnv:
    if int(num_envs) < 1:
        raise ValueError(f"num_envs must be >= 1, got {num_envs}")
    make_one = functools.partial(gym.make, env_id, **kwargs)
    first = make_one()  # validates the arguments once, and tells the reward mode
    fns = [functools.partial(_made, first)] + [make_one] * (int(num_envs) - 1)
    if first.unwrapped.config.reward_mode == "vector":
        from mo_gymnasium.wrappers.vector import MOSyncVectorEnv

        return MOSyncVectorEnv(fns)
    return gym.vector.SyncVectorEnv(fns)


def _made(env: gym.Env) -> gym.Env:
    return env


def _circuit_id(kwargs: Mapping[str, Any]) -> str:
    """The registered id whose arguments (circuit, world) ``kwargs`` carry, else an id of their circuit, else the
    first one. It names the specs of the environments; ``kwargs`` (which hold the circuit and the world) make them."""
    scenario = kwargs.get("scenario")
    world_ids = {None: ENV_IDS, **WORLD_IDS}
    for ids in (world_ids.get(scenario, ()) if scenario is None or isinstance(scenario, str) else (), ENV_IDS):
        for env_id in ids:
            if gym.spec(env_id).kwargs.get("track") == kwargs.get("track"):
                return env_id
    return ENV_IDS[0]
