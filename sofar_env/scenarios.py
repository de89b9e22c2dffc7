"""World scenarios: ``"paper"`` (the paper's world) and ``"interactive"`` (a world in which gamma matters).

The worlds are values of the configuration layer (:data:`sofar_env.configs.registry.WORLD_REGISTRY`); this
module describes them and keeps the former names (:data:`SCENARIOS`, :func:`scenario_overrides`) as views.
"paper" names the world here; the controller preset ``stack="paper"`` and the observation layout
``observation="paper"`` are independent of it (see the registry's docstring).

A scenario is a named set of overrides of :class:`~sofar_env.config.EnvConfig`, applied before the
user's own keys (which therefore win). ``stack`` picks the controller, ``scenario`` the world; the two
combine freely.

``"paper"`` (the default, the ``SOfAR-<Circuit>-v0`` ids)
    The plant is the MPC's own kinematic bicycle, the controllers see the opponents exactly, and the
    opponents drive a fixed lateral offset at a fixed pace ratio rho, blind to the ego.

``"interactive"`` (the ``SOfAR-<Circuit>-Interactive-v0`` ids)
    * **Plant**: the kinematic bicycle, as in the paper world (``"dynamic"`` below puts this world on
      the tyre model).
    * **Opponents that race back** (:mod:`sofar_env.opponents`): each car's pace drawn per episode as
      rho x U(0.9, 1.1), lifts (a Poisson rate of one per 60 s per car, to 80 % pace for 4 s); each car
      drives its own smooth line (up to 1.5 m from its offset); cars defend: a car with the ego closing
      within 5 - 60 m behind makes at most one move toward the ego's line per approach and none once the
      ego is alongside (a quarter of the cars never defend); they never leave the track or overlap.
    * **Sensing** (:mod:`sofar_env.sensing`): the controllers and the observation see the opponents with
      correlated noise (1.0 m along, 0.3 m across, 0.5 m/s; 0.3 s correlation time) and 0.2 s of latency.
      Collisions, track limits and overtakes are judged on the true state. The stack predicts each car's
      lateral motion from its sensed lateral rate (``StackConfig.lateral_prediction``).
    * **Observation**: the extended 16-value layout of :mod:`sofar_env.observation` (``observation="extended"``):
      the paper's 12 values plus the two nearest opponents' sensed lateral rates, the heading error and the
      smallest barrier value. ``observation="paper"`` gives the 12 values, e.g. for a policy trained in the
      paper world.

``"dynamic"`` (the ``SOfAR-<Circuit>-Dynamic-v0`` ids)
    The interactive world, everything above, on the **dynamic single-track plant with Pacejka tyres**
    (:mod:`sofar_env.dynamics`: tyre forces on loads that change with downforce and braking, a friction
    ellipse, steering and powertrain lags, mu drawn per episode in U(0.8, 1.0)). The controller keeps its
    kinematic model: model mismatch, as on a real car. What the world sets so that the two fit (the reasons
    and the probes behind each value: ``docs/decisions/dynamic-world-settings.md``):

    * **The car's yaw-rate loop** (``race.dynamic.yaw_rate_gain`` = 2): the steering servo aims at the
      MPC's angle plus a correction toward the kinematic bicycle's yaw rate at that angle.
    * **Limits inside the tyres' grip at the lowest mu** (0.8, no downforce): ``vehicle.lat_acc_max`` =
      8.5 m/s^2 and ``vehicle.a_min`` = -7 m/s^2, a box inside the friction ellipse; the ego's
      ``speed_factor`` = 0.7 puts the speed profile inside those limits; cars start at 0.5-0.7 of the
      profile (``race.start_speed_fraction``).
    * **Room for the tracking error**: ``stack.mpc.track_margin`` = 2.2 m (half the width plus 1.25 m
      instead of 0.25 m).
    * **Calmer steering**: ``stack.mpc.q`` n-weight 20 instead of 150, ``stack.mpc.r`` steering-rate
      weight 50 instead of 8.

    These stack settings are part of the world (the plant and the sensed traffic ask for them); they are
    applied on top of a named ``stack`` preset too, and the user's own stack keys win. The observation is
    the interactive world's 16 values.
"""

from __future__ import annotations

from typing import Any

from .configs.registry import WORLD_REGISTRY, NameView, world_overrides

__all__ = ["SCENARIOS", "scenario_overrides"]

SCENARIOS = NameView(WORLD_REGISTRY)
"""Names accepted by the ``scenario`` key: the worlds of :data:`~sofar_env.configs.registry.WORLD_REGISTRY`
(``"paper"``, ``"interactive"``, ``"dynamic"``), a live view that compares equal to their tuple."""


def scenario_overrides(name: str) -> dict[str, Any]:
    """The configuration overrides of scenario ``name`` (a fresh nested dict); ``ValueError`` for an unknown
    name."""
    return world_overrides(name)
