"""Named reward terms of the SOfAR environments (pure functions of one control step).

The reward is a vector of five objectives, in the order of
:data:`~sofar_env.config.OBJECTIVE_NAMES`:

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

With a decision interval k > 1 the environments sum the vectors of the k control steps.
:func:`safety_cost` is the matching per-step cost for constrained RL.
"""

from __future__ import annotations

import math

import numpy as np

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


def reward_vector(*, collision: bool, off_track: bool, overtakes: int, progress: float, profile_speed: float,
                  dt: float, barrier_slack: float, min_h: float, gamma: float, previous_gamma: float) -> np.ndarray:
    """The five objectives of one control step (float64, order of ``OBJECTIVE_NAMES``)."""
    return np.array([
        safety_term(collision, off_track),
        overtake_term(overtakes),
        progress_term(progress, profile_speed, dt),
        barrier_margin_term(barrier_slack, min_h),
        gamma_smoothness_term(gamma, previous_gamma),
    ])


def scalarize(vector: np.ndarray, weights: np.ndarray) -> float:
    """Linear scalarisation ``weights . vector`` as a Python float."""
    return float(np.dot(np.asarray(weights, float), np.asarray(vector, float)))


def safety_cost(collision: bool, off_track: bool, barrier_slack: float) -> float:
    """Cost for constrained RL: barrier slack used (units of h) + 1 per collision + 1 per leaving the track."""
    return max(0.0, float(barrier_slack)) + float(bool(collision)) + float(bool(off_track))
