"""The reward objectives, defined once: name, reward term, bounds, default weight, reference preference.

:data:`OBJECTIVES` is the one registry of the reward vector's components, in the order of the vector.
Everything else is derived from it: :data:`OBJECTIVE_NAMES` (the order), the fields of
:class:`~sofar_env.configs.env.RewardWeights` and their defaults, :func:`~sofar_env.rewards.reward_vector`
(each entry's ``term`` evaluated on one control step's :class:`StepOutcome`), and the deployment preference
the training scripts start from (:data:`REFERENCE_PREFERENCE`). Adding a reward term is one entry here (a
new field of :class:`RewardWeights` is declared from it).

The term functions are defined here too (with their own arguments; :mod:`sofar_env.rewards` re-exports
them). Contract of a term: a pure function of one :class:`StepOutcome` returning a Python float; the environments
sum the terms over the control steps of a decision. Bounds are per control step (``math.inf`` where a term
is unbounded).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass


__all__ = ["Objective", "StepOutcome", "OBJECTIVES", "OBJECTIVE_NAMES", "REFERENCE_PREFERENCE", "objective",
           "safety_term", "overtake_term", "progress_term", "barrier_margin_term", "gamma_smoothness_term"]


def safety_term(collision: bool, off_track: bool) -> float:
    """-1 on a collision or leaving the track, else 0."""
    return -1.0 if (collision or off_track) else 0.0


def overtake_term(overtakes: int) -> float:
    """+1 per overtake in the step."""
    return float(overtakes)


def progress_term(progress: float, profile_speed: float, dt: float) -> float:
    """Arc length gained [m] normalised by what the speed profile would cover in ``dt`` [s]."""
    return float(progress) / (max(float(profile_speed), 1.0) * float(dt))


def barrier_margin_term(barrier_slack: float, min_h: float) -> float:
    """-min(1, barrier_slack + max(0, -min_h)); 0 when no slack is used and every h >= 0."""
    depth = -min_h if math.isfinite(min_h) and min_h < 0.0 else 0.0
    return -min(1.0, max(0.0, float(barrier_slack)) + depth)


def gamma_smoothness_term(gamma: float, previous_gamma: float) -> float:
    """-|gamma_t - gamma_{t-1}|."""
    return -abs(float(gamma) - float(previous_gamma))


@dataclass(slots=True)
class StepOutcome:
    """What one control step of one car gives the reward terms (the keyword arguments of
    :func:`~sofar_env.rewards.reward_vector`)."""

    collision: bool
    off_track: bool
    overtakes: int
    progress: float
    """Arc length gained in the step [m]."""
    profile_speed: float
    """The speed profile at the car's arc length before the step [m/s]."""
    dt: float
    """The control period [s]."""
    barrier_slack: float
    """The largest DCBF slack of the MPC solution [-]."""
    min_h: float
    """The smallest barrier value over the opponents after the step [-]."""
    gamma: float
    previous_gamma: float


@dataclass(frozen=True)
class Objective:
    """One component of the reward vector."""

    name: str
    """Key of the objective: its field of ``RewardWeights``, its entry of ``objective_names``."""
    term: Callable[[StepOutcome], float]
    """The reward term of one control step."""
    bounds: tuple[float, float]
    """Range of the term per control step."""
    default_weight: float
    """Default weight in the scalar reward (``RewardWeights``)."""
    reference_preference: float
    """Share of the objective in the reference implementation's deployment preference (PASTA and the
    linear-reward PPO baseline start from it)."""
    doc: str
    """What the term measures."""


OBJECTIVES: tuple[Objective, ...] = (
    Objective("safety", lambda o: safety_term(o.collision, o.off_track), (-1.0, 0.0), 10.0, 0.31,
              "-1 if the car collided or left the track, else 0."),
    Objective("overtakes", lambda o: overtake_term(o.overtakes), (0.0, math.inf), 1.0, 0.45,
              "Number of opponents overtaken in the step (+1 each)."),
    Objective("progress", lambda o: progress_term(o.progress, o.profile_speed, o.dt), (-math.inf, math.inf),
              0.05, 0.05,
              "Arc length gained over what the speed profile covers in dt (about 1 at the profile, about 0.8 at "
              "the default speed_factor; negative backwards)."),
    Objective("barrier_margin", lambda o: barrier_margin_term(o.barrier_slack, o.min_h), (-1.0, 0.0), 0.5,
              0.04,
              "-min(1, barrier_slack + max(0, -min_h)): the DCBF slack used plus how deep the car is inside the "
              "nearest barrier ellipse."),
    Objective("gamma_smoothness", lambda o: gamma_smoothness_term(o.gamma, o.previous_gamma), (-0.95, 0.0),
              0.1, 0.15,
              "-|gamma_t - gamma_{t-1}| (only the first control step of a decision can be non-zero)."),
)
"""The objectives, in the order of the reward vector."""

OBJECTIVE_NAMES: tuple[str, ...] = tuple(o.name for o in OBJECTIVES)
"""Names of the reward objectives, in the order of the reward vector."""

REFERENCE_PREFERENCE: tuple[float, ...] = tuple(o.reference_preference for o in OBJECTIVES)
"""Deployment preference of the reference implementation, in the order of :data:`OBJECTIVE_NAMES`
(0.31, 0.45, 0.05, 0.04, 0.15)."""


def objective(name: str) -> Objective:
    """The objective called ``name``; ``KeyError`` naming the valid names otherwise."""
    for o in OBJECTIVES:
        if o.name == name:
            return o
    raise KeyError(f"unknown objective {name!r}; objectives: {', '.join(OBJECTIVE_NAMES)}")
