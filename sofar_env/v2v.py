"""V2V: controlled cars predict each other from the plans they publish.

Without it every controlled car predicts the others from what it senses, rows ``(s, n, v)``: at
constant speed, or (``stack.pace_prediction``, the default) at a constant pace ratio
``v / v_profile(s)`` along the circuit's speed profile. With ``race.v2v`` each controlled car
publishes the arc lengths of its MPC prediction over the horizon (the last solved one, made one
control step earlier), and every other controlled car is handed, for that car's row, the speed
``v`` with which *its own* predictor reproduces the published plan: the arc length the plan
reaches at the end of the receiver's MPC horizon. With constant-speed prediction that is the
plan's mean speed over the horizon; with pace prediction it is the pace ratio that covers the
same distance along the speed profile in the same time, ``rho = (T(s + ds) - T(s)) / t`` with
``T`` the profile's travel time, times ``v_profile(s)``.

A plan is an intention, made under that car's own predictions of the others; the sensed speed is a
measurement. The receiver takes the more cautious of the two: for a car ahead of it the smaller
speed (it may brake as planned, it will not be further ahead than either says), for a car behind it
the larger (it may accelerate as planned). The row's position is the sensed one; only its speed
changes, so the MIQP and the MPC (which predict opponents from that speed) see the plan, and the
observation, the rewards and collision checks are unaffected. A car whose last MPC step did not
solve (a fallback) publishes nothing and is predicted as without V2V.

Pure functions of the track's speed profile and a published plan; :mod:`sofar_env.core` applies
them.
"""

from __future__ import annotations

import numpy as np

from .stack.prediction import TravelTime

__all__ = ["TravelTime", "published_advance", "speed_for_advance"]


def published_advance(times: np.ndarray, s_pred: np.ndarray, v_last: float, elapsed: float,
                      horizon: float) -> float:
    """Arc length [m] a published plan covers from ``elapsed`` to ``elapsed + horizon`` [s] after it was made.

    ``times`` (N+1,) and ``s_pred`` (N+1,) are the plan's stage times [s] and arc lengths [m]; beyond
    its last stage the plan continues at its last speed ``v_last`` [m/s].
    """
    def at(t: float) -> float:
        if t <= times[-1]:
            return float(np.interp(t, times, s_pred))
        return float(s_pred[-1]) + max(float(v_last), 0.0) * (t - float(times[-1]))

    return max(at(elapsed + horizon) - at(elapsed), 0.0)


def speed_for_advance(travel_time: TravelTime | None, s: float, advance: float, horizon: float) -> float:
    """The speed [m/s] at arc length ``s`` with which a predictor covers ``advance`` [m] in ``horizon`` [s].

    ``travel_time`` None: constant-speed prediction (``advance / horizon``); otherwise pace prediction
    along the profile of ``travel_time`` (see the module docstring).
    """
    if travel_time is None:
        return advance / horizon
    track = travel_time.track
    s0 = float(track.wrap(s))
    rho = float(travel_time(s0 + advance) - travel_time(s0)) / horizon
    return rho * max(float(track.speed(s0)), 0.1)
