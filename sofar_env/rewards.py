"""Named reward terms of the SOfAR environments (pure functions of one control step).

The reward is a vector of five objectives, in the order of
:data:`~sofar_env.configs.objectives.OBJECTIVE_NAMES`:

====================  ==========  ==========================================================================
objective             range       per control step
====================  ==========  ==========================================================================
``safety``            {-1, 0}     -1 if the car collided or left the track, else 0
``overtakes``         {0, 1, ..}  number of opponents overtaken in the step
``progress``          ~[0, 1.3]   arc length gained / (speed profile at the start of the step x dt); about 1
                                  when driving at the circuit's speed profile (0.8 at the default
                                  speed_factor), negative when going backwards
``barrier_margin``    [-1, 0]     -min(1, barrier_slack + max(0, -min_h)): the largest DCBF slack of the MPC
                                  solution (units of h) plus how deep the car is inside the nearest barrier
                                  ellipse after the step (min_h over the opponents; h < 0 inside, h >= -1)
``gamma_smoothness``  [-0.95, 0]  -abs(gamma_t - gamma_{t-1}) (only the first control step of a decision
                                  can be non-zero)
====================  ==========  ==========================================================================

The objectives (name, term, bounds, default weight, reference preference) are defined once, in
:mod:`sofar_env.configs.objectives`; this module evaluates them. With a decision interval k > 1 the
environments sum the vectors of the k control steps.
:func:`safety_cost` is the matching per-step cost for constrained RL.
"""

from __future__ import annotations

import numpy as np

from .configs.objectives import (OBJECTIVES, StepOutcome, barrier_margin_term, gamma_smoothness_term,
                                 overtake_term, progress_term, safety_term)

__all__ = [
    "safety_term",
    "overtake_term",
    "progress_term",
    "barrier_margin_term",
    "gamma_smoothness_term",
    "reward_vector",
    "scalarize",
    "safety_cost",
]


def reward_vector(*, collision: bool, off_track: bool, overtakes: int, progress: float, profile_speed: float,
                  dt: float, barrier_slack: float, min_h: float, gamma: float, previous_gamma: float) -> np.ndarray:
    """The objectives of one control step (float64, order of ``OBJECTIVE_NAMES``): each entry of
    :data:`~sofar_env.configs.objectives.OBJECTIVES` evaluated on the step."""
    step = StepOutcome(collision, off_track, overtakes, progress, profile_speed, dt, barrier_slack, min_h, gamma,
                       previous_gamma)
    return np.array([o.term(step) for o in OBJECTIVES])


def scalarize(vector: np.ndarray, weights: np.ndarray) -> float:
    """Linear scalarisation ``weights . vector`` as a Python float."""
    return float(np.dot(np.asarray(weights, float), np.asarray(vector, float)))


def safety_cost(collision: bool, off_track: bool, barrier_slack: float) -> float:
    """Cost for constrained RL: barrier slack used (units of h) + 1 per collision + 1 per leaving the track."""
    return max(0.0, float(barrier_slack)) + float(bool(collision)) + float(bool(off_track))
