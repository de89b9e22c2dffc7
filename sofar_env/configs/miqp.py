"""Parameters of the passing-side MIQP (:class:`MIQPConfig`)."""

from __future__ import annotations

from dataclasses import dataclass

from ..domains import check_fields, choice, flag, integer, neutral, real

__all__ = ["MIQPConfig"]


@dataclass(frozen=True)
class MIQPConfig:
    """Parameters of the passing-side MIQP."""

    nodes: int = integer(76, ge=2)
    """Number of coarse horizon nodes N [-] (node k is at time k * node_dt)."""
    node_dt: float = real(0.15, gt=0.0, unit="s")
    """Time between nodes [s]; the horizon spans (nodes - 1) * node_dt (11.25 s)."""
    w_dev: float = real(1.0, gt=0.0, unit="1/m^2")
    """Weight of the deviation (d_k - n_ref_k)^2 [1/m^2]."""
    w_smooth: float = real(100.0, ge=0.0, unit="1/m^2")
    """Weight of the smoothness (d_{k+1} - d_k)^2 [1/m^2]."""
    w_prev: float = real(1.0, ge=0.0, unit="1/m^2")
    """Weight of the consistency (d_k - d_prev_k)^2 with the previous plan [1/m^2]."""
    w_switch: float = real(500.0, ge=0.0)
    """Hysteresis: cost of choosing a side different from the previous decision for
    the same opponent [-] (per opponent, (b - b_prev)^2 is linear in binary b)."""
    w_slack: float = real(5e4, ge=0.0, unit="1/m")
    """L1 penalty on the Big-M slack xi [1/m]."""
    safe_lat: float = real(3.75, ge=0.0, unit="m")
    """Lateral clearance from an opponent's centreline when passing it [m]."""
    safe_lon: float = real(8.0, ge=0.0, unit="m")
    """Longitudinal half-window [m]: an opponent's side constraint is active where
    the ego and its prediction are closer than this along the track. Coverage
    between nodes is handled separately (both end nodes of every node interval that
    touches the window are constrained, see :mod:`sofar_env.planning.clearance`), so
    this is the car length plus a margin, not a node-spacing allowance; the effective
    window is at most one relative step (relative speed * node_dt) wider on each side."""
    closing_decel: float = real(0.0, ge=0.0, unit="m/s^2")
    """Deceleration [m/s^2] that sizes the braking-distance extension of the side-constraint
    window; 0 disables it (plain box window ``|gap| < safe_lon``). With a value ``a_b > 0``
    the window grows on the side the cars close in, by ``L = v_close^2 / (2 a_b)`` (the
    closing speed ``v_close`` from the ego's node speed and the opponent's speed), and the
    clearance there tapers elliptically: ``safe_lat * sqrt(1 - ((|gap| - safe_lon) / L)^2)``.
    This is the shape of the MPC's velocity-aware barrier (``a = a0 + v_close^2 / (2
    a_brake)``), so a plan that keeps it does not cross an opponent's lane inside its
    braking distance, which the barrier would forbid; the stack sets it to the barrier's
    ``a_brake``."""
    closing_stride: int = integer(3, ge=1)
    """In the braking-distance extension of the window (beyond ``safe_lon``), the
    clearance is imposed at every this-many-th node only, counted from the box window
    (the clearance decreases away from the box, so a kept node requires at least what
    the dropped nodes beyond it would): the extension spans up to ~20 nodes at high
    closing speed, and every pair adds two rows to the MIQP (solve time grows with
    them). The box window keeps every node; 1 keeps every node of the extension too."""
    window_shape: str = choice("box", ("box", "ellipse"))
    """Shape of the side-constraint window: ``"box"`` (``safe_lat`` wherever ``|gap| < safe_lon``,
    tapering elliptically over the braking-distance extension beyond it) or ``"ellipse"`` (``safe_lat
    sqrt(1 - (gap / A)^2)`` for ``|gap| < A``, ``A = safe_lon`` plus the braking-distance extension on the
    side the cars close in): the shape of the MPC's barrier, with ``safe_lon`` its longitudinal semi-axis
    at zero closing speed."""
    track_margin: float = real(1.2, ge=0.0, unit="m")
    """Distance kept from each track edge [m]."""
    continuity: float = real(0.3, ge=0.0, unit="m")
    """Maximum |d_0 - ego_n| [m] (ego_n clipped into the corridor first, so the
    constraint can never be infeasible)."""
    cluster_gap: float = real(10.0, ge=0.0, unit="m")
    """Opponents closer than this to each other along the track [m], at a node where
    the ego overlaps either of them, share one side decision (no threading between
    them); linking is transitive."""
    alongside_gap: float = real(0.0, ge=0.0, unit="m")
    """Side lock for cars alongside [m]: an opponent whose arc-length gap to the ego is below
    this now keeps the ego on the side of it where the ego is (its cluster's binary is fixed to
    that side): two cars alongside cannot swap sides through each other; and two such cars on
    either side of the ego are never linked into one cluster (the ego is already between them).
    0 (the default) turns the lock off; multi-car races set it through ``race.side_lock``. Decision:
    ``docs/decisions/multi-car-defaults.md``."""
    free_plan: str = neutral(choice("raceline", ("raceline", "smooth")))
    """The plan where no opponent is relevant (none within its clearance window over the horizon):
    ``"raceline"`` (the default) returns ``n_ref`` clipped into the corridor before any problem is built, without
    the continuity bound of node 0, the smoothness or the consistency cost: where the last car of a pass drops out
    of the window, the lateral reference steps from the car's offset to the raceline at once. ``"smooth"`` solves
    the same QP as with opponents, without side constraints (continuity, deviation, smoothness and consistency
    costs, the corridor): the plan returns to the raceline as smoothly as every other plan moves. Decision:
    ``docs/decisions/dynamic-world-settings.md``, "The departures"."""
    solver: str = choice("daqp", ("daqp", "enumerate"))
    """"daqp" (DAQP branch-and-bound) or "enumerate" (one QP per side pattern)."""
    incumbent: bool = flag(True)
    """Start DAQP's branch-and-bound from an incumbent: the objective of the previous plan, moved to each
    side pattern's side of the clearance, bounds the optimum (DAQP's ``fval_bound``), so that nodes which
    cannot beat it end early (:mod:`sofar_env.planning.solvers`). The same plan to the bit, in less time;
    False searches without it (for comparison). Only with ``solver="daqp"``."""
    daqp_cycle_tol: int = neutral(integer(10, ge=1))
    """DAQP's ``cycle_tol`` in every QP of the passing planner (branch-and-bound and enumeration): how many
    consecutive active-set iterations without progress DAQP allows before it exits with its cycling flag, upon
    which the planner falls back to its previous plan (counted). 10, DAQP's own default, is the default. With a
    car alongside over the whole horizon (multi-car races at equal pace) the planner's QP has a clearance row at
    every node and DAQP's degenerate steps exceed 10: it exits at QPs whose optimum it reaches with 100. A QP
    that never reaches the limit is solved to the same bits under any value [-], >= 1. Decision:
    ``docs/decisions/planner-cycling.md``."""

    def __post_init__(self) -> None:
        check_fields(self, "stack.miqp")
