"""Configuration of the low-level MPC-DCBF (:class:`MPCConfig`) and of its barrier (:class:`BarrierParams`).
Values only: the controller is :mod:`sofar_env.control.mpc`, the barrier :mod:`sofar_env.control.barrier`."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..domains import check_fields, choice, flag, integer, nested, neutral, real, reals, text
from ..errors import ConfigError

__all__ = ["BarrierParams", "MPCConfig", "TRACK_ROWS"]


@dataclass(frozen=True)
class BarrierParams:
    """Parameters of the velocity-aware elliptic barrier."""

    a0: float = real(7.0, gt=0.0, unit="m")
    """Longitudinal semi-axis at zero closing speed [m]."""
    b: float = real(2.7, gt=0.0, unit="m")
    """Lateral semi-axis [m]."""
    a_brake: float = real(10.0, gt=0.0, unit="m/s^2")
    """Braking capability used for the braking-distance term of the semi-axis [m/s^2]."""
    sigma: float = real(2.0, gt=0.0, unit="m")
    """Gap scale of the ahead/behind blend tanh(ds / sigma) of the closing speed [m]."""
    sharpness: float = real(4.0, gt=0.0, unit="s/m")
    """Sharpness k of the softplus smooth max(0, v_close) [s/m]."""
    heading_extent: float = real(0.0, ge=0.0, unit="m")
    """Widening of the lateral semi-axis with the heading error e of the ego to the track and the course
    angle c of the opponent: ``b + heading_extent (|sin e|_eps + |sin c|_eps)``, with the smooth
    ``|x|_eps = sqrt(x^2 + eps^2) - eps``, eps = 0.01 (the opponent's course angle where it is known, see
    :func:`barrier_expr`). 0 (the default): the ellipse of aligned cars [m], >= 0. Multi-car races set it
    through ``race.heading_extent``; decision: ``docs/decisions/multi-car-defaults.md``."""
    heading_sides: str = neutral(choice("both", ("both", "toward")))
    """Which turns of the ego widen the lateral semi-axis (only with ``heading_extent`` > 0). ``"both"`` (the
    default): every turn, by ``|sin e|_eps``, whichever way the car points. ``"toward"``: with the opponent ahead
    only as far as the ego's front end swings towards it, with the opponent behind only as far as its rear end
    does; alongside (within about ``heading_extent`` of the opponent's reference point) every turn as with
    ``"both"``, blended smoothly (:func:`~sofar_env.control.barrier.barrier_expr`). A car behind another and
    turned away from it reaches no closer to it than an aligned one. Decision:
    ``docs/decisions/heading-sides.md``."""

    def __post_init__(self) -> None:
        check_fields(self, "stack.mpc.barrier")


TRACK_ROWS = ("reference", "ends", "recoverable", "recoverable-curved")
"""The values of :attr:`MPCConfig.track_rows`."""


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
    track_buffer: float = neutral(real(0.0, ge=0.0, unit="m"))
    """*Buffer slack* (0: off, the default; only with end rows, ``track_rows`` other than ``"reference"``). The
    first ``track_buffer`` metres by which a track row is violated are paid for by a second slack of the stage,
    weighted ``track_buffer_slack`` instead of ``track_slack``: with the buffer of ``track_margin`` (0.25 m
    beyond the car's half width) as this band, a car that stands inside the buffer pays little to drive along
    it and out, while the edge itself stays as expensive as without it [m], in [0, ``track_margin``). Decision:
    ``docs/decisions/stall-fixes.md``."""
    track_buffer_slack: tuple = neutral(reals((2e3, 2e4), size=2, ge=0.0))
    """(L1, L2) weights of the buffer slack [1/m, 1/m^2] (only with ``track_buffer``)."""
    track_rows: str = choice("reference", TRACK_ROWS)
    """What the soft track constraints bound: ``"reference"``, the reference point's offset ``n`` (the
    paper's form; a caller may tighten the edges for the car's length, as the stack's footprint-aware
    edges do with the heading error of the previous plan), or ``"ends"``, the offsets ``n +- l sin e`` of
    both ends of the car (``l = max(l_f, l_r)`` of the vehicle), linearised at each iterate, so that the
    QP sees that turning towards the track's direction brings the ends in, or ``"recoverable"``, the ends
    with room kept for turning back to the track's direction at full lock, so that the car never stands
    turned towards an edge it cannot drive away from (:mod:`.ends`), or ``"recoverable-curved"``, that room
    counted with the track's curvature at each stage (in a corner a car turned towards the outside edge needs
    more). These have four track rows per stage instead of two and always include them."""
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
    qp_solver: str = choice("piqp", ("piqp", "osqp", "daqp"))
    """QP backend: "piqp" (sparse interior point, accurate, the default), "daqp" (the same QP condensed onto
    the 2 N input steps, slacks as soft rows with their own weights, DAQP's dense active set; agrees with
    PIQP to PIQP's tolerance) or "osqp" (less accurate, comparison only)."""
    qp_fallback: str = neutral(choice("off", ("off", "daqp")))
    """A second backend for the QPs the first one fails on: "off" (the default: a failed QP makes the MPC fall
    back to the shifted previous plan or a brake) or "daqp" (the same QP solved by the condensed DAQP backend;
    only where ``qp_solver`` is another backend). Counted in ``MPCDCBF.n_qp_fallbacks``. PIQP can fail on a
    feasible QP far outside its soft track rows, e.g. a start from rest deep inside the track margin. Decision:
    ``docs/decisions/qp-backend.md``."""
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
    ``race.mpc_restart_slack``) [-], > 0. Decision: ``docs/decisions/multi-car-defaults.md``."""

    def __post_init__(self) -> None:
        check_fields(self, "stack.mpc")
        for name in ("lat_acc_slack", "track_slack", "barrier_slack", "track_buffer_slack"):
            if not getattr(self, name)[1] > 0.0:
                raise ConfigError(f"stack.mpc.{name} must be (L1 >= 0, L2 > 0), got {getattr(self, name)!r}")
        if self.track_buffer > 0.0:
            if self.track_rows == "reference":
                raise ConfigError("stack.mpc.track_buffer needs end rows (stack.mpc.track_rows other than "
                                  f"'reference'), got track_buffer = {self.track_buffer!r} with 'reference' rows")
            if not self.track_buffer < self.track_margin:
                raise ConfigError(f"stack.mpc.track_buffer must be < track_margin = {self.track_margin} [m], got "
                                  f"{self.track_buffer!r}")

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
