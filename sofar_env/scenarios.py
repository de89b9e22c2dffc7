"""World scenarios: ``"paper"`` (the paper's world) and ``"interactive"`` (a world in which gamma matters).

A scenario is a named set of overrides of :class:`~sofar_env.config.EnvConfig`, applied before the
user's own keys (which therefore win). ``stack`` picks the controller, ``scenario`` the world; the two
combine freely.

``"paper"`` (the default, the ``SOfAR-<Circuit>-v0`` ids)
    The plant is the MPC's own kinematic bicycle, the controllers see the opponents exactly, and the
    opponents drive a fixed lateral offset at a fixed pace ratio rho, blind to the ego.

``"interactive"`` (the ``SOfAR-<Circuit>-Interactive-v0`` ids)
    * **Plant**: for now the kinematic bicycle, as in the paper world. The dynamic single-track plant
      with Pacejka tyres (:mod:`sofar_env.dynamics`, ``race={"plant": "dynamic"}``, mu drawn per episode)
      is available and tested, but the kinematic MPC does not yet drive it stably: the closed loop
      oscillates laterally (yaw-rate deviations of 0.2 - 0.3 rad/s) and leaves the track within 5 - 40 s
      in most episodes, so it is not part of this scenario until the controller handles it. With it,
      lower ``vehicle.lat_acc_max`` to what the tyres give at the episode's mu (about 10 m/s^2 at the
      lowest mu of the range without downforce). What we measured towards that: softer lateral
      weights (``stack={"mpc": {"q": (0, 20, 0, 2.5, 0), "r": (0.01, 50)}}`` instead of n-weight 150
      and steering-rate weight 8) remove the limit cycle on straights, and with a speed profile for
      75 % of the tyres' grip at the lowest mu (about 1.1-1.2 x the lap time) the car laps Laguna
      Seca, Monza and Kentucky alone for 60-100 s without leaving the track; but with opponents it
      still leaves the track within 3-45 s: braking hard while cornering (the rear axle saturates) and
      lateral tracking errors of 0.3-0.5 m where the raceline runs 2 m from an edge. A kinematic MPC
      needs the yaw dynamics (a dynamic prediction model or a yaw-rate loop) for this plant.
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
"""

from __future__ import annotations

from typing import Any

__all__ = ["SCENARIOS", "scenario_overrides"]

SCENARIOS: tuple[str, ...] = ("paper", "interactive")
"""Names accepted by the ``scenario`` key."""

_INTERACTIVE: dict[str, Any] = {
    "observation": "extended",
    "race": {
        "sensor": {"enabled": True},
        "opponents": {
            "pace": {"spread": 0.1, "lift_rate": 1.0 / 60.0},
            "lines": {"amplitude": 1.5},
            "defence": {"enabled": True},
        },
    },
}


def scenario_overrides(name: str) -> dict[str, Any]:
    """The configuration overrides of scenario ``name`` (a fresh nested dict)."""
    key = name.strip().lower() if isinstance(name, str) else name
    if key == "paper":
        return {}
    if key == "interactive":
        import copy

        return copy.deepcopy(_INTERACTIVE)
    raise ValueError(f"unknown scenario {name!r}; valid scenarios: {', '.join(SCENARIOS)}")
