"""Settings of the bug-compatible controller (:mod:`sofar_env.control.refnum`), with their reference values.

Every default is the value of the reference implementation of the paper; changing one switches a defect
off, which is how the sweep of :mod:`sofar_agents.evaluation.refnum` attributes the collapse of Table I's
extremes to its cause.
"""

from __future__ import annotations

from dataclasses import dataclass

from ..domains import check_fields, choice, custom, flag, integer, nested, real

__all__ = ["ReferenceNumerics", "HPIPMOptions", "MODES", "PHANTOM_S", "PHANTOM_SLOT_STEP"]

MODES = {"speed_abs": 0, "speed": 1, "balance": 2, "robust": 3}
"""HPIPM's ``enum hpipm_mode``."""


@dataclass(frozen=True)
class HPIPMOptions:
    """Options of HPIPM's dense interior-point method (``d_dense_qp_ipm_arg``)."""

    mode: str = choice("balance", tuple(MODES))
    """Preset the other options start from: ``speed_abs``, ``speed``, ``balance`` or ``robust``."""
    iter_max: int = integer(50, ge=1)
    """Iteration cap; HPIPM returns status ``max_iter`` when it is reached [-]."""
    mu0: float = real(1.0, gt=0.0)
    """Initial barrier parameter [-]."""
    alpha_min: float = real(1e-8, gt=0.0)
    """Smallest step; a shorter step ends the solve with status ``min_step`` [-]."""
    tol_stat: float = real(1e-6, gt=0.0)
    """Tolerance on the stationarity residual [-]."""
    tol_eq: float = real(1e-8, gt=0.0)
    """Tolerance on the equality residual [-]."""
    tol_ineq: float = real(1e-8, gt=0.0)
    """Tolerance on the inequality residual [-]."""
    tol_comp: float = real(1e-8, gt=0.0)
    """Tolerance on the complementarity residual [-]."""

    def __post_init__(self) -> None:
        check_fields(self, "stack.reference_numerics.qp")


def _spacing_table(value) -> str | None:
    """None if ``value`` is a tuple of (circuit name, positive factor) pairs, else what is wrong."""
    try:
        pairs = [(str(name), float(f)) for name, f in value]
    except (TypeError, ValueError):
        return "must be (circuit, factor) pairs"
    if not all(f > 0.0 and f < float("inf") for _, f in pairs):
        return "factors must be positive and finite"
    return None

PHANTOM_S = 99999.0
"""Arc-length gap at which the reference places an opponent that is not on its target line [m]."""
PHANTOM_SLOT_STEP = 100.0
"""Empty slot i is placed at ``PHANTOM_S + PHANTOM_SLOT_STEP * i`` with speed 0 [m]."""


@dataclass(frozen=True)
class ReferenceNumerics:
    """The reference implementation's numerics, reproduced defect by defect (see the package docstring)."""

    phantoms: bool = flag(True)
    """Fill every opponent slot: an opponent off the target line (behind the ego or beyond the window) at
    ``(PHANTOM_S, 0, its speed)``, an empty slot at ``(PHANTOM_S + 100 i, 0, 0)``. False: such slots get
    no DCBF rows (what a correct implementation does)."""
    slots: int = integer(4, ge=1)
    """Opponent slots of the OCP [-]."""
    window_points: int = integer(150, ge=1)
    """Segments of the target line an opponent must project onto to be real (not a phantom) [-]."""
    point_spacing: tuple = custom((("LagunaSeca", 1.0), ("Monza", 1.5), ("Indianapolis", 0.5), ("Kentucky", 0.787)),
                                  _spacing_table, "(circuit, factor > 0) pairs")
    """Spacing of the target line's points per circuit, as a multiple of ``max(0.1 v, 1.5)`` m (the
    reference samples its raceline files, whose point spacing differs per circuit); 1.0 elsewhere."""
    lower_bound: float = real(-1e9, lt=0.0)
    """Lower bound of the soft track and DCBF rows (the rows are ``<= 0``). HPIPM cannot meet its
    complementarity tolerance on a row this far from its bound, and a DCBF row of a phantom (h of
    order 1e9) can reach it."""
    first_transition_dcbf: bool = flag(False)
    """Impose the DCBF on the transition x_0 -> x_1 (acados v0.4.3 puts path constraints on nodes
    1..N-1 only: False)."""
    zero_command_on_failure: bool = flag(True)
    """On a failed solve apply throttle 0 and steer towards delta = 0 (the reference simulator); False:
    brake at half the braking limit instead. Either way the iterate is kept, not reset."""
    max_iter_is_failure: bool = flag(False)
    """Count HPIPM's iteration cap as a failed solve. acados' SQP_RTI accepts that status (False); only
    a too-short step or a NaN is a failure."""
    qp: HPIPMOptions = nested(HPIPMOptions)
    """HPIPM's options (acados' defaults for its dense solver)."""
    a0: float = real(3.0, gt=0.0, unit="m")
    """Longitudinal semi-axis of the reference barrier at zero closing speed [m]."""
    b: float = real(1.25, gt=0.0, unit="m")
    """Lateral semi-axis of the reference barrier [m]."""
    margin: float = real(0.5, ge=0.0)
    """The reference barrier is ``(ds/a)^2 + (dn/b)^2 - (1 + margin)`` [-]."""
    a_brake: float = real(10.0, gt=0.0, unit="m/s^2")
    """Braking deceleration of the barrier's closing-speed term ``max(0, v - v_o)^2 / (2 a_brake)`` [m/s^2]."""
    track_margin: float = real(1.2, ge=0.0, unit="m")
    """Distance kept between the reference point and the track edges [m], >= 0 (the project's margin,
    ``MPCConfig.track_margin``, not the reference's). Decision: ``docs/decisions/reference-numerics-track-margin.md``."""
    lat_acc_max: float = real(15.0, gt=0.0, unit="m/s^2")
    """Bound on |a_lat| [m/s^2] (soft)."""
    rk_steps: int = integer(4, ge=1)
    """ERK steps per shooting interval (Kutta's third-order scheme, acados' ``ERK`` with 3 stages) [-]."""
    cost_scaled: bool = flag(True)
    """Multiply the stage costs and slack penalties by the interval length, as acados v0.4.3 does."""

    def __post_init__(self) -> None:
        check_fields(self, "stack.reference_numerics")

    def spacing(self, circuit: str | None) -> float:
        """Target-line spacing factor of a circuit (1.0 for circuits not listed)."""
        return dict(self.point_spacing).get(circuit or "", 1.0)
