"""The bug-compatible MPC on a synthetic road: the closed loop in which its failures were first measured.

A straight-and-corner road (300 m straights at a 48 m/s reference, 300 m corners of 60 m radius at
17.6 m/s, 12 m wide), the MPC's own Frenet model as the plant (RK4, 10 sub-steps per 0.1 s, the steering
angle of node 1 applied directly), two real opponents kept 120-500 m ahead (re-placed when the ego comes
closer) and two phantom slots ``(99999, 0, rho x (60, 40) m/s)``; the ego starts at 20 m/s. On a failed
solve the plant gets throttle 0 and steering 0, as in the reference simulator. :func:`road_loop` counts the
failed solves and says when the car left the road (|n| > 20 m). The same loop run with acados' own
SQP_RTI / FULL_CONDENSING_HPIPM on the same OCP gave the failure pattern the docs page quotes; this
module re-makes it with :class:`~sofar_env.control.refnum.ReferenceNumericsMPC`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["RoadLoop", "road_loop"]

_WHEELBASE, _LR = 2.9718, 1.2933


def _road(s):
    corner = (np.asarray(s, float) // 300.0) % 2 == 1
    return np.where(corner, 1.0 / 60.0, 0.0), np.where(corner, 0.8 * 22.0, 0.8 * 60.0)


def _plant(x: np.ndarray, a: float, delta: float, kappa: float) -> np.ndarray:
    """0.1 s of the Frenet bicycle with slip, steering angle held at ``delta``, RK4 in 10 steps."""
    x = x.copy()
    x[4] = delta
    h = 0.01

    def rhs(z):
        beta = np.arctan(_LR / _WHEELBASE * np.tan(z[4]))
        s_dot = z[3] * np.cos(z[2] + beta) / (1.0 - kappa * z[1])
        return np.array([s_dot, z[3] * np.sin(z[2] + beta),
                         z[3] / _WHEELBASE * np.cos(beta) * np.tan(z[4]) - kappa * s_dot, a, 0.0])

    for _ in range(10):
        k1 = rhs(x)
        k2 = rhs(x + h / 2 * k1)
        k3 = rhs(x + h / 2 * k2)
        k4 = rhs(x + h * k3)
        x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return x


@dataclass(frozen=True)
class RoadLoop:
    """Outcome of :func:`road_loop`."""

    gamma: float
    rho: float
    steps: int
    """Control steps run (fewer than asked when the car left the road)."""
    failures: int
    """Failed MPC solves (each followed by throttle 0, steering 0)."""
    left_road_at: float | None
    """Simulated time at which |n| passed 20 m [s], or None."""
    qp_status: dict
    """HPIPM statuses counted (0 success, 1 iteration cap, 2 too-short step, 3 NaN)."""


def road_loop(gamma: float, rho: float, steps: int, phantoms: bool = True, cache_dir: str | None = None) -> RoadLoop:
    """Drive the synthetic road for ``steps`` control steps of 0.1 s at barrier decay ``gamma``, opponents at
    pace ``rho``; ``phantoms=False`` puts the two extra slots on real far opponents instead."""
    from sofar_env.control.mpc import MPCConfig, MPCStageData
    from sofar_env.control.refnum import ReferenceNumerics, ReferenceNumericsMPC

    mpc = ReferenceNumericsMPC(MPCConfig(first_step=0.075, cache_dir=cache_dir), ReferenceNumerics(track_margin=0.85))
    n = mpc.config.horizon
    t = mpc.config.time_grid()
    x = np.array([0.0, 0.0, 0.0, 20.0, 0.0])
    opp_s = np.array([250.0, 450.0])
    failures = 0
    for step in range(steps):
        kappa, v_ref = _road(x[0] + t * max(x[3], 1.0))
        opp_v = rho * _road(opp_s)[1] / 0.8
        slots = np.array([[opp_s[0] - x[0], 0.0, opp_v[0]], [opp_s[1] - x[0], 0.0, opp_v[1]],
                          [99999.0, 0.0, 60.0 * rho], [99999.0, 0.0, 40.0 * rho]])
        if not phantoms:
            slots[2] = (opp_s[1] - x[0] + 150.0, 0.0, opp_v[1])
            slots[3] = (opp_s[1] - x[0] + 300.0, 0.0, opp_v[1])
        stage = MPCStageData(kappa=kappa, n_ref=np.zeros(n + 1), v_ref=v_ref, n_min=np.full(n + 1, -6.0),
                             n_max=np.full(n + 1, 6.0))
        res = mpc.solve_slots(np.array([0.0, *x[1:]]), stage, slots, gamma)
        if res.success:
            a, delta = float(res.u_pred[0, 0]), float(np.clip(res.x_pred[1, 4], -0.25, 0.25))
        else:
            failures += 1
            a, delta = 0.0, 0.0
        x = _plant(x, a, delta, float(_road(x[0])[0]))
        opp_s = opp_s + opp_v * 0.1
        for i in range(2):
            if opp_s[i] - x[0] < 120.0:
                opp_s[i] = x[0] + 400.0 + 100.0 * i
        if abs(x[1]) > 20.0 or not np.all(np.isfinite(x)):
            return RoadLoop(gamma, rho, step + 1, failures, round(0.1 * (step + 1), 1), dict(mpc.qp_status_counts))
    return RoadLoop(gamma, rho, steps, failures, None, dict(mpc.qp_status_counts))
