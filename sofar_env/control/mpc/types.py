"""What the MPC-DCBF takes and returns: its configuration, the per-stage track data, the result.

Also the check of the arguments of a solve (:func:`validate_arguments`): malformed
arguments are the only thing the controller raises for (``ValueError``).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from ...configs.mpc import TRACK_ROWS, BarrierParams, MPCConfig  # noqa: F401  (defined in the configuration layer)
from .assembly import all_finite

__all__ = ["MPCConfig", "MPCStageData", "MPCResult", "STATUS_SOLVED", "STATUS_FALLBACK_SHIFT",
           "STATUS_FALLBACK_BRAKE", "validate_arguments"]



STATUS_SOLVED = "solved"
STATUS_FALLBACK_SHIFT = "fallback_shift"
STATUS_FALLBACK_BRAKE = "fallback_brake"




@dataclass
class MPCStageData:
    """Per-stage data, arrays of length N+1, evaluated at the predicted arc lengths
    :meth:`MPCDCBF.predicted_s` (plus the ego's absolute s)."""

    kappa: np.ndarray
    """Curvature of the reference line [1/m] (entry k is used on the interval k -> k+1)."""
    n_ref: np.ndarray
    """Lateral reference, e.g. the MIQP profile d* [m]."""
    v_ref: np.ndarray
    """Speed reference [m/s]."""
    n_min: np.ndarray
    """Right track edge, -width_right [m] (raw; the MPC applies track_margin)."""
    n_max: np.ndarray
    """Left track edge, +width_left [m] (raw; the MPC applies track_margin)."""


@dataclass(frozen=True)
class MPCResult:
    """Outcome of one MPC solve."""

    u: np.ndarray
    """(2,) control to apply now, (a [m/s^2], delta_dot [rad/s]), within the hard bounds."""
    x_pred: np.ndarray
    """(N+1, 5) predicted Frenet states, s relative to the ego [m]."""
    u_pred: np.ndarray
    """(N, 2) predicted inputs."""
    status: str
    """"solved" | "fallback_shift" | "fallback_brake"."""
    success: bool
    """True when the QP (or NLP) was solved."""
    slack: dict
    """Largest slack per kind: {"lat_acc" [m/s^2], "track" [m], "barrier" [-]}."""
    h_now: float | Callable[[], float]
    """What :attr:`barrier_min` is: its value, or a call that returns it (:class:`~.rti.DeferredBarrierMin`)."""
    solve_time: float
    """Wall-clock time of the call [s]."""
    qp_iterations: int
    """Interior-point (or ADMM) iterations, summed over the SQP iterations."""
    sqp_iterations: int = 0
    """Number of QPs solved in this call."""
    barrier_slack_first: float = 0.0
    """Largest DCBF slack of the first transition x_0 -> x_1 [-]: when it is ~0 the
    executed step satisfies the DCBF condition (up to model error)."""
    n_opponents: int = 0
    """Number of opponents with DCBF rows in the QP."""
    qp_time: float = 0.0
    """Wall-clock time spent inside the QP solver (PIQP/OSQP set-up, update and solve) [s]."""
    qp_fallbacks: int = 0
    """QPs of this solve that the backend failed on and ``MPCConfig.qp_fallback`` solved."""

    @cached_property
    def barrier_min(self) -> float:
        """Min over all given opponents of h at the current state [-] (inf if none).

        Evaluated on first access where the solve deferred it (``h_now`` a call): no decision of the controller
        or the environment reads it (diagnostics do), and with the heading-widened barrier its numpy evaluation
        costs about 5 % of an environment step. The value is the same either way, to the bit."""
        h = self.h_now
        return float(h()) if callable(h) else float(h)


def validate_arguments(x0, stage, opponents, gamma, horizon: int):
    """Checked copies ``(x0, arrays, opponents, gamma)`` of the arguments of a solve.

    ``x0`` becomes a (5,) float array with s set to 0, ``arrays`` the (5, N+1) rows
    (kappa, n_ref, v_ref, n_min, n_max) of ``stage``, ``opponents`` an (M, 3) or (M, 4)
    float array. Raises ``ValueError`` for malformed arguments.
    """
    try:
        gamma = float(gamma)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"gamma must be a real number, got {gamma!r}") from exc
    if not (math.isfinite(gamma) and 0.0 <= gamma <= 1.0):
        raise ValueError(f"gamma must be finite and in [0, 1], got {gamma!r}")
    x0 = np.array(x0, dtype=float).reshape(-1)
    if x0.shape != (5,) or not all_finite(x0):
        raise ValueError(f"x0 must be 5 finite values (s, n, e, v, delta), got {x0!r}")
    x0[0] = 0.0
    if not isinstance(stage, MPCStageData):
        raise ValueError("stage must be an MPCStageData")
    try:
        arrays = np.array([stage.kappa, stage.n_ref, stage.v_ref, stage.n_min, stage.n_max], dtype=float)
    except ValueError as exc:
        raise ValueError(f"stage arrays must all have {horizon + 1} values") from exc
    if arrays.shape != (5, horizon + 1) or not all_finite(arrays):
        raise ValueError(f"stage arrays must be {horizon + 1} finite values each, got shape {arrays.shape}")
    opp = np.asarray(opponents, dtype=float)
    if opp.size == 0:
        opp = np.zeros((0, 3))
    if opp.ndim != 2 or opp.shape[1] not in (3, 4) or not all_finite(opp):
        raise ValueError(f"opponents must be an (M, 3) array of finite (s_rel, n, v) or an (M, 4) array of "
                         f"finite (s_rel, n, v, n_dot), got shape {opp.shape}")
    return x0, arrays, opp, gamma
