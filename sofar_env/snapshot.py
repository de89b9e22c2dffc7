"""Saved moments of the environments: what their ``get_state()`` returns and their ``set_state()`` takes.

An :class:`EnvState` holds a deep copy of everything that evolves in an environment: the simulation
core (:class:`~sofar_env.core.ControlledRace`: the race world, every controller with its warm start,
its passing-side plan and the data its QP solvers were set up with, the per-car counters, the
sensors) and the environment's random generator. Restoring it and applying the same actions
reproduces what followed the saved moment to the bit.

The circuit (:class:`~sofar_env.tracks.Track`) and the configuration are never changed by a race:
a state shares them with the environment it was taken from instead of copying them, and restoring it
puts the environment's own circuit back in place of the state's. A state is picklable (its circuit
and configuration travel with it) and may be restored any number of times: :func:`restore_parts`
hands out a fresh copy each time.

Wrappers keep state of their own that a state of the environment does not hold (for instance
Gymnasium's ``TimeLimit`` counts its steps). The SOfAR environments end their episodes at the race
duration themselves; to copy a wrapped environment as a whole, use ``copy.deepcopy`` or pickle.
"""

from __future__ import annotations

import copy
import dataclasses
from dataclasses import dataclass
from typing import Any

__all__ = ["EnvState", "Snapshots", "take_state", "restore_parts", "same_config"]


@dataclass(frozen=True, eq=False)
class EnvState:
    """A saved moment of a SOfAR environment (see the module docstring); treat it as opaque.

    Taken by ``get_state()`` of :class:`~sofar_env.env.SOfARRaceEnv` and
    :class:`~sofar_env.multi_agent.SOfARParallelEnv`; ``set_state()`` of an environment of the same
    class, the same number of cars and an equal configuration restores it.
    """

    kind: str
    """The class name of the environment it was taken from."""
    config: Any
    """That environment's configuration (:class:`~sofar_env.config.EnvConfig`)."""
    n_cars: int
    """Its number of controlled cars."""
    parts: dict
    """The saved attributes of the environment, by name (deep copies)."""


class Snapshots:
    """``get_state()`` / ``set_state()`` and pickling for the environment classes (a mixin).

    The class names in ``_state_attributes`` the attributes that evolve (its simulation core ``core`` first);
    it has ``config`` and may have a ``_renderer``.
    """

    _state_attributes: tuple[str, ...] = ("core",)

    def get_state(self) -> EnvState:
        """The current moment of the environment, for :meth:`set_state` (see :mod:`sofar_env.snapshot`).

        A deep copy of the race world, every controller (warm starts, plans, the data of its QP solvers),
        the counters and the random generator; the circuit and the configuration are shared. Changes
        nothing; the state is picklable and stays valid whatever the environment does next.
        """
        parts = {name: getattr(self, name) for name in self._state_attributes}
        core = self.core
        return take_state(type(self).__name__, self.config, core.n_cars, parts, core.track)

    def set_state(self, state: EnvState) -> None:
        """Return to a moment saved by :meth:`get_state`: the same actions then give the same steps, to the bit.

        ``state`` must come from an environment of the same class, number of cars and configuration
        (this one, a copy of it, or one made with the same arguments); otherwise ``ValueError`` is raised
        and nothing changes. The state itself is not consumed: it can be restored again. Wrappers keep
        their own state (e.g. ``TimeLimit``'s step count), which this does not restore.
        """
        core = self.core
        parts = restore_parts(state, type(self).__name__, self.config, core.n_cars, core.track)
        for name, value in parts.items():
            setattr(self, name, value)

    def __getstate__(self) -> dict:
        """Everything but the renderer (a figure or a window; made again by the next ``render()``)."""
        state = self.__dict__.copy()
        if "_renderer" in state:
            state["_renderer"] = None
        return state


def take_state(kind: str, config: Any, n_cars: int, parts: dict[str, Any], track: Any) -> EnvState:
    """An :class:`EnvState` of deep copies of ``parts`` that share ``config`` and ``track`` (None before the
    first reset) instead of copying them."""
    return EnvState(kind, config, int(n_cars), _copy(parts, {id(config): config, id(track): track}))


def restore_parts(state: Any, kind: str, config: Any, n_cars: int, track: Any) -> dict[str, Any]:
    """Fresh deep copies of the saved attributes of ``state`` for an environment of class ``kind`` with
    ``config``, ``n_cars`` cars and the circuit ``track`` (None before its first reset), which replace the
    state's circuit and configuration in them.

    Raises ``ValueError`` (and copies nothing) when ``state`` is not an :class:`EnvState` of such an
    environment.
    """
    if not isinstance(state, EnvState):
        raise ValueError(f"set_state() takes what get_state() returned (an EnvState), got {type(state).__name__}")
    if state.kind != kind or state.n_cars != int(n_cars):
        raise ValueError(f"this state was taken from a {state.kind} with {state.n_cars} car(s), "
                         f"not from a {kind} with {n_cars}")
    if not same_config(state.config, config):
        raise ValueError("this state was taken from an environment with another configuration")
    saved_track = getattr(state.parts.get("core"), "track", None)
    memo: dict[int, Any] = {id(state.config): config}
    if saved_track is not None:
        memo[id(saved_track)] = saved_track if track is None else track
    return _copy(state.parts, memo)


def same_config(a: Any, b: Any) -> bool:
    """Whether two environment configurations are equal; two :class:`~sofar_env.tracks.Track` objects (a
    circuit of your own) count as equal when their name, length, raceline, widths and speed profile are."""
    if a is b:
        return True
    if type(a) is not type(b) or not dataclasses.is_dataclass(a):
        return False
    for f in dataclasses.fields(a):
        x, y = getattr(a, f.name), getattr(b, f.name)
        if f.name == "track" and not isinstance(x, str) and not isinstance(y, str):
            if not _same_track(x, y):
                return False
        elif not (x is y or x == y):
            return False
    return True


def _same_track(a: Any, b: Any) -> bool:
    import numpy as np

    if a is b:
        return True
    try:
        return (type(a) is type(b) and a.name == b.name and a.length == b.length
                and all(np.array_equal(getattr(a, k), getattr(b, k)) for k in ("s", "xy", "kappa", "w_left", "w_right", "v")))
    except AttributeError:
        return False


def _copy(parts: dict[str, Any], memo: dict[int, Any]) -> dict[str, Any]:
    """``copy.deepcopy(parts)`` with the objects of ``memo`` (keys: ids of originals) put in place of copies."""
    memo = dict(memo)
    memo.pop(id(None), None)
    return copy.deepcopy(parts, memo)
