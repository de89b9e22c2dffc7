"""Scripted opponent cars: raceline followers at a pace ratio, respawned once overtaken.

By default (the paper's field) each opponent drives along the raceline at a
constant lateral offset at ``rho`` times the speed profile, ignoring the ego and
each other. Behaviours that make them race back, all off by default, are
configured in :class:`OpponentConfig`: per-car paces and lifts, own lines, and
defending against the ego with racing etiquette.

* :mod:`~sofar_env.opponents.config`: the configuration dataclasses;
* :mod:`~sofar_env.opponents.field`: :class:`Opponents`, the state of the field
  (motion, overtakes and respawn, poses);
* :mod:`~sofar_env.opponents.pace`, :mod:`~sofar_env.opponents.lines`,
  :mod:`~sofar_env.opponents.defence`: the behaviours (pure functions and small
  per-car state);
* :mod:`~sofar_env.opponents.traffic` and :mod:`~sofar_env.opponents.steering`:
  one step along and across the track of an interactive field, built on the
  lateral tracker and edge bands of :mod:`~sofar_env.opponents.lateral`.
"""

from .config import DefenceConfig, LineConfig, OpponentConfig, PaceConfig, TrafficConfig
from .field import Opponents

__all__ = ["OpponentConfig", "PaceConfig", "LineConfig", "DefenceConfig", "TrafficConfig", "Opponents"]
