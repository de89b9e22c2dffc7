"""What the MPC-DCBF takes and returns: its configuration, the per-stage track data, the result.

Also the check of the arguments of a solve (:func:`validate_arguments`): malformed
arguments are the only thing the controller raises for (``ValueError``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ...domains import check_fields, choice, flag, integer, nested, real, reals, text
from ...errors import ConfigError
from ..barrier import BarrierParams
from .assembly import all_finite

__all__ = ["MPCConfig", "MPCStageData", "MPCResult", "STATUS_SOLVED", "STATUS_FALLBACK_SHIFT",
           "STATUS_FALLBACK_BRAKE", "validate_arguments"]

TRACK_ROWS = ("reference", "ends", "recoverable")
"""The values of :attr:`MPCConfig.track_rows`."""

STATUS_SOLVED = "solved"
STATUS_FALLBACK_SHIFT = "fallback_shift"
STATUS_FALLBACK_BRAKE = "fallback_brake"


@dataclass(frozen=True)
class MPCConfig:
    """Configuration of the MPC-DCBF."""

    horizon: int = integer(20, ge=2)
    """N, number of shooting intervals [-]."""
    ts: float = real(0.075, gt=0.0, unit="s")
    """Length of the shooting intervals after the first one [s]."""
    control_dt: float = real(0.1, ge=0.0, unit="s")
    """Plant period, i.e. the time between two solves; the warm start is shifted by it [s].
    0 disables the shift (repeated solves at one state then iterate SQP to convergence)."""
    first_step: float | None = real(None, gt=0.0, optional="control_dt", unit="s")
    """Length of the first shooting interval [s]; None: ``control_dt`` (or ``ts`` when
    ``control_dt`` is 0), so the first DCBF transition spans exactly one plant period."""
    q: tuple = reals((0.0, 150.0, 0.0, 2.5, 0.0), size=5, ge=0.0)
    """Diagonal state weights on (s, n, e, v, delta) [1/m^2, 1/m^2, 1/rad^2, s^2/m^2, 1/rad^2]."""
    r: tuple = reals((0.01, 8.0), size=2, gt=0.0)
    """Diagonal input weights on (a, delta_dot) [s^4/m^2, s^2/rad^2]."""
    lat_acc_slack: tuple = reals((4e3, 4e3), size=2, ge=0.0)
    """(L1, L2) weights of the lateral-acceleration slack [s^2/m, s^4/m^2]; cost z*sigma + Z*sigma^2/2."""
    track_slack: tuple = reals((3.5e4, 6e4), size=2, ge=0.0)
    """(L1, L2) weights of the track-boundary slack [1/m, 1/m^2]."""
    barrier_slack: tuple = reals((9e4, 9e4), size=2, ge=0.0)
    """(L1, L2) weights of the DCBF slack [-] (h is dimensionless)."""
    track_margin: float = real(1.2, ge=0.0, unit="m")
    """Distance kept between the car's reference point and each track edge [m]
    (half width 0.95 m + 0.25 m buffer)."""
    track_rows: str = choice("reference", TRACK_ROWS)
    """What the soft track constraints bound: ``"reference"``, the reference point's offset ``n`` (the
    paper's form; a caller may tighten the edges for the car's length, as the stack's footprint-aware
    edges do with the heading error of the previous plan), or ``"ends"``, the offsets ``n +- l sin e`` of
    both ends of the car (``l = max(l_f, l_r)`` of the vehicle), linearised at each iterate, so that the
    QP sees that turning towards the track's direction brings the ends in, or ``"recoverable"``, the ends
    with room kept for turning back to the track's direction at full lock, so that the car never stands
    turned towards an edge it cannot drive away from (:mod:`.ends`). Both have four track rows per stage
    instead of two and always include them."""
    max_opponents: int = integer(4, ge=0)
    """Number of opponent slots in the QP [-]."""
    opponent_range_ahead: float = real(150.0, ge=0.0, unit="m")
    """Opponents with an arc-length gap above this are ignored [m]."""
    opponent_range_behind: float = real(40.0, ge=0.0, unit="m")
    """Opponents more than this behind the ego are ignored [m]."""
    opponent_h_keep: float = real(8.0, gt=-1.0, inf="keep every candidate")
    """Opponents whose barrier h stays above this along the warm start (and whose DCBF rows
    are all inactive by more than ``opponent_dcbf_keep``) get no rows in this QP [-].
    h = 8 is three times the ellipse's size. Use inf to keep every candidate."""
    opponent_dcbf_keep: float = real(0.5, ge=0.0)
    """DCBF inactivity margin of the rule above [-]."""
    barrier: BarrierParams = nested(BarrierParams)
    """Barrier function parameters."""
    qp_solver: str = choice("piqp", ("piqp", "osqp"))
    """QP backend: "piqp" (accurate, default) or "osqp" (less accurate, comparison only)."""
    compile: bool = flag(True)
    """Compile the CasADi stage function to C (cached on disk); falls back to CasADi evaluation."""
    cache_dir: str | None = text(None, optional="the default cache")
    """Cache of compiled libraries; None: $SOFAR_CACHE_DIR, $XDG_CACHE_HOME/sofar or ~/.cache/sofar."""
    extra_iteration_when_active: bool = flag(True)
    """Run a second SQP iteration when a barrier constraint is near-active: with an opponent
    close, one RTI step from the shifted plan keeps less distance than the converged solution."""
    barrier_active_tol: float = real(0.05, ge=0.0)
    """A DCBF row counts as near-active when its linearised residual exceeds -this value [-]."""
    cold_start_iterations: int = integer(3, ge=1)
    """SQP iterations when there is no previous plan to warm-start from [-]."""
    integrator_substeps: int = integer(1, ge=1)
    """RK4 sub-steps per shooting interval [-]."""
    qp_eps_abs: float = real(1e-7, gt=0.0)
    """Absolute tolerance of the QP solver [-]."""
    qp_eps_rel: float = real(1e-9, gt=0.0)
    """Relative tolerance of the QP solver [-]."""
    qp_max_iter: int = integer(100, ge=1)
    """Iteration limit of the QP solver [-]."""
    restart_slack: float = real(math.inf, gt=0.0, inf="off")
    """A warm-started solve whose largest DCBF slack exceeds this is solved once more from a cold guess
    (constant lateral offset, never through an opponent ahead), and the result with the smaller DCBF
    slack is kept (:mod:`.rti`, "Restart"). inf: never (the default; multi-car races set it through
    ``race.mpc_restart_slack``) [-]."""

    def __post_init__(self) -> None:
        check_fields(self, "stack.mpc")
        for name in ("lat_acc_slack", "track_slack", "barrier_slack"):
            if not getattr(self, name)[1] > 0.0:
                raise ConfigError(f"stack.mpc.{name} must be (L1 >= 0, L2 > 0), got {getattr(self, name)!r}")

    @property
    def dt0(self) -> float:
        """Length of the first shooting interval [s]."""
        if self.first_step is not None:
            return float(self.first_step)
        return float(self.control_dt) if self.control_dt > 0.0 else float(self.ts)

    def time_grid(self) -> np.ndarray:
        """(N+1,) prediction times t_k [s]."""
        t = np.empty(self.horizon + 1)
        t[0] = 0.0
        t[1:] = self.dt0 + self.ts * np.arange(self.horizon)
        return t


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
    barrier_min: float
    """Min over all given opponents of h at the current state [-] (inf if none)."""
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
