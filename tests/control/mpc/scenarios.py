"""Shared test inputs of the MPC tests: stage data on a constant road and the numeric plant."""

import numpy as np

from sofar_env.control.mpc import MPCStageData
from sofar_env.vehicle import AV21, frenet_rhs, rk4_step

N = 20


def make_stage(v_ref=40.0, n_ref=0.0, kappa=0.0, half_width=6.0, n=N):
    return MPCStageData(kappa=np.full(n + 1, kappa), n_ref=np.full(n + 1, n_ref), v_ref=np.full(n + 1, v_ref),
                        n_min=np.full(n + 1, -half_width), n_max=np.full(n + 1, half_width))


def plant_step(x, u, dt, kappa=0.0):
    """Numeric Frenet plant: RK4 of the same model, two sub-steps per control period."""
    return np.array(rk4_step(lambda xx, uu: frenet_rhs(xx, uu, kappa, AV21), list(x), list(u), dt, 2))
