"""The initial guess of a solve: the previous plan shifted in time, or a cold guess without one.

Both solvers (the RTI and the IPOPT reference) start from it: the previous solution
shifted by ``control_dt`` (linear interpolation of the states, zero-order hold of the
inputs, linear extrapolation past the horizon) and re-anchored so the ego is at
``s = 0``; without a plan (first solve, after a reset or a brake fallback) a constant
speed guess that does not drive through an opponent ahead.
"""

from __future__ import annotations

import math

import numpy as np

from ..._jit import kernel, maximum, minimum
from ...vehicle import VehicleParams
from ..barrier import BarrierParams
from .types import MPCConfig

__all__ = ["PlanShift", "cold_guess"]


class PlanShift:
    """Shift of a plan by ``control_dt``, precomputed as one matrix ``x_guess = W @ x_plan``."""

    def __init__(self, cfg: MPCConfig, vehicle: VehicleParams):
        self.vehicle = vehicle
        t = cfg.time_grid()
        n_h = cfg.horizon
        t_ext = t[-1] + max(cfg.control_dt, cfg.ts) + cfg.ts
        ratio = (t_ext - t[-1]) / (t[-1] - t[-2])
        extend = np.zeros((n_h + 2, n_h + 1))  # x_plan -> (x_plan, extrapolated point)
        extend[: n_h + 1, : n_h + 1] = np.eye(n_h + 1)
        extend[n_h + 1, n_h] = 1.0 + ratio
        extend[n_h + 1, n_h - 1] = -ratio
        te = np.concatenate([t, [t_ext]])
        q = t + cfg.control_dt
        j = np.clip(np.searchsorted(te, q, side="right") - 1, 0, n_h)
        w = (q - te[j]) / (te[j + 1] - te[j])
        interp = np.zeros((n_h + 1, n_h + 2))
        interp[np.arange(n_h + 1), j] = 1.0 - w
        interp[np.arange(n_h + 1), j + 1] += w
        self.weights = interp @ extend
        """(N+1, N+1) W: linear interpolation in time, linear extrapolation past t_N."""
        self.input_index = np.clip(np.searchsorted(t, q[:-1] + 1e-9, side="right") - 1, 0, n_h - 1)
        """(N,) index of the planned input held at each shifted stage (zero-order hold)."""

    def __call__(self, xs: np.ndarray, us: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Plan (xs (N+1, 5), us (N, 2)) shifted by control_dt, re-anchored at s = 0, delta and v in bounds."""
        xg = self.weights @ xs
        _anchor_and_bound(xg, self.vehicle.steer_max)
        return xg, us[self.input_index]


@kernel
def _anchor_and_bound(xg, steer_max):
    """``xg`` (N+1, 5) in place: s re-anchored at ``s_0 = 0``, delta clipped to +-``steer_max``, v to >= 0;
    one compiled call of the numpy form ``xg[:, 0] -= xg[0, 0]``, ``minimum(maximum(delta, -steer_max),
    steer_max)``, ``maximum(v, 0)`` (:mod:`sofar_env._jit`). ``np.maximum(-0.0, 0.0)`` is ``+0.0`` (the
    second operand on a tie of zeros), so v is written out here rather than with ``_jit.maximum``."""
    s0 = xg[0, 0]
    for k in range(xg.shape[0]):
        xg[k, 0] -= s0
        xg[k, 4] = minimum(maximum(xg[k, 4], -steer_max), steer_max)
        v = xg[k, 3]
        xg[k, 3] = v if (v > 0.0 or math.isnan(v)) else 0.0


def cold_guess(x0: np.ndarray, t: np.ndarray, vehicle: VehicleParams, bp: BarrierParams,
               opponents: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Guess ``(x (N+1, 5), u (N, 2))`` at times ``t`` without a previous plan.

    Constant speed and lateral offset, but never driving through an opponent that is
    ahead in the ego's lane (the guess then stays ``a0`` behind it): a guess that
    crosses an opponent linearises the barrier near its centre, where its gradient
    vanishes, and the first QP becomes badly conditioned.
    """
    v0 = max(float(x0[3]), 0.0)
    s = v0 * t
    if opponents is not None and len(opponents):
        ahead = (opponents[:, 0] > 0.0) & (np.abs(opponents[:, 1] - x0[1]) < bp.b)
        if np.any(ahead):
            o = opponents[ahead]
            cap = (o[None, :, 0] + o[None, :, 2] * t[:, None] - bp.a0).min(axis=1)
            s = np.maximum.accumulate(np.clip(np.minimum(s, cap), 0.0, None))
    xg = np.zeros((len(t), 5))
    xg[:, 0] = s
    xg[:, 1] = x0[1]
    xg[1:, 3] = np.diff(s) / np.diff(t)
    xg[0, 3] = v0
    u = np.zeros((len(t) - 1, 2))
    u[:, 0] = np.clip(np.diff(xg[:, 3]) / np.diff(t), vehicle.a_min, vehicle.a_max)
    return xg, u
