"""The named configurations: controller presets and worlds, as frozen values with their documentation.

Two registries, each a mapping ``name -> Entry(value, doc)``:

* :data:`STACK_PRESET_REGISTRY`: the controllers the ``stack`` key names; each value is a frozen
  :class:`~sofar_env.configs.stack.StackConfig`. :func:`sofar_env.stack.stack_preset` and
  :data:`sofar_env.stack.STACK_PRESETS` are views of it. A new preset is one entry
  (:func:`register_stack_preset`).
* :data:`WORLD_REGISTRY`: the worlds the ``scenario`` key names; each value is a frozen :class:`World`, the
  overrides of :class:`~sofar_env.configs.env.EnvConfig` the world applies (:mod:`sofar_env.scenarios` has the
  full description of each world).

How the entries combine with each other and with the user's keys is :mod:`sofar_env.configs.resolve`.

**The three meanings of "paper".** The word names three independent things, each after the paper the project
reproduces:

* the *world* ``scenario="paper"`` (the default, the ``SOfAR-<Circuit>-v0`` ids): the paper's race, a
  kinematic plant, perfect sensing, opponents on fixed offsets at a fixed pace ratio;
* the *controller preset* ``stack="paper"``: the paper's Algorithm 1 as written, every addition of the
  project off (the default controller is ``"sofar"``, now ``"sofar-6"``);
* the *observation layout* ``observation="paper"``: the paper's 12 observation values (the default of the
  paper world; the interactive worlds default to ``"extended"``).

Each can be chosen without the others (``scenario="interactive", stack="paper", observation="paper"``). The
names are public keys used by scripts and committed results, so they stay.
"""

from __future__ import annotations

import copy
import dataclasses
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any, NamedTuple

from .refnum import ReferenceNumerics
from .stack import StackConfig

__all__ = ["Entry", "World", "DEFAULT_STACK_PRESET", "STACK_PRESET_REGISTRY", "WORLD_REGISTRY", "OBSERVATION_LAYOUTS",
           "NameView", "default_stack", "register_stack_preset", "stack_preset", "world", "world_overrides"]


class Entry(NamedTuple):
    """One named configuration: its frozen value and what it is."""

    value: Any
    doc: str


def _freeze(value: Any) -> Any:
    """A read-only deep copy of nested mappings (lists become tuples)."""
    if isinstance(value, Mapping):
        return MappingProxyType({k: _freeze(v) for k, v in value.items()})
    if isinstance(value, list):
        return tuple(_freeze(v) for v in value)
    return value


def _thaw(value: Any) -> Any:
    """A plain, mutable deep copy of a frozen mapping."""
    if isinstance(value, Mapping):
        return {k: _thaw(v) for k, v in value.items()}
    return copy.deepcopy(value)


@dataclass(frozen=True)
class World:
    """A world: the overrides of :class:`~sofar_env.configs.env.EnvConfig` it applies, read-only.

    ``overrides`` may hold ``race``, ``observation`` and ``stack`` keys (nested mappings of field overrides);
    the ``stack`` part is the world's controller settings, applied on top of any named preset.
    """

    overrides: Mapping[str, Any]

    def __post_init__(self) -> None:
        object.__setattr__(self, "overrides", _freeze(self.overrides))

    def as_overrides(self) -> dict[str, Any]:
        """The overrides as a fresh nested dict (the caller may change it)."""
        return _thaw(self.overrides)


class NameView(Sequence):
    """The names of a registry, in registration order, read live (a registered name shows at once).

    Compares equal to the tuple of the same names, so code written for the former tuple constants
    (``"paper" in STACK_PRESETS``, ``", ".join(STACK_PRESETS)``, argparse ``choices=``) keeps working.
    """

    def __init__(self, registry: Mapping[str, Entry]) -> None:
        self._registry = registry

    def __getitem__(self, index):  # type: ignore[override]
        return tuple(self._registry)[index]

    def __len__(self) -> int:
        return len(self._registry)

    def __iter__(self) -> Iterator[str]:
        return iter(tuple(self._registry))

    def __contains__(self, name: object) -> bool:
        return name in self._registry

    def __eq__(self, other: object) -> bool:
        return tuple(self) == (tuple(other) if isinstance(other, (tuple, NameView)) else other)

    __hash__ = None  # type: ignore[assignment]

    def __repr__(self) -> str:
        return repr(tuple(self))


# ------------------------------------------------------------------ controller presets
def _paper() -> StackConfig:
    base = StackConfig()
    return dataclasses.replace(base, follow=False, parked_pass=False, pace_prediction=False, lateral_prediction=False,
                               footprint_edges=False, miqp=dataclasses.replace(base.miqp, closing_decel=0.0))


def _reference_numerics(phantoms: bool) -> StackConfig:
    paper = _paper()
    grid = dataclasses.replace(paper.mpc, first_step=paper.mpc.ts)  # the reference's uniform grid
    return dataclasses.replace(paper, mpc=grid, reference_numerics=ReferenceNumerics(phantoms=phantoms))


def _track_rows(rows: str) -> StackConfig:
    base = StackConfig()
    return dataclasses.replace(base, mpc=dataclasses.replace(base.mpc, track_rows=rows))


def _sofar_4() -> StackConfig:
    return dataclasses.replace(StackConfig(), restart_lateral_weight=15.0, follow_creep_speed=2.0,
                               slow_rows_speed=10.0, slow_rows_exit_speed=12.0, slow_rows_curved=True)


def _sofar_5() -> StackConfig:
    base = _sofar_4()
    return dataclasses.replace(base, mpc=dataclasses.replace(base.mpc, qp_fallback="daqp"))


def _sofar_6() -> StackConfig:
    return dataclasses.replace(_sofar_5(), restart_buffer_edge=0.05)


def _sofar_7() -> StackConfig:
    return dataclasses.replace(_sofar_6(), restart_horizon=80)


def _sofar_8() -> StackConfig:
    return dataclasses.replace(_sofar_7(), restart_heading_extent=2.45)


def _sofar_9() -> StackConfig:
    return dataclasses.replace(_sofar_6(), restart_buffer_scale=0.25)


def _sofar_10() -> StackConfig:
    return dataclasses.replace(_sofar_6(), follow_queue=True)


def _sofar_11() -> StackConfig:
    base = _sofar_10()
    barrier = dataclasses.replace(base.mpc.barrier, heading_extent=2.45)
    return dataclasses.replace(base, mpc=dataclasses.replace(base.mpc, barrier=barrier))


def _sofar_12() -> StackConfig:
    base = _sofar_11()
    return dataclasses.replace(base, miqp=dataclasses.replace(base.miqp, free_plan="smooth"))


def _sofar_13() -> StackConfig:
    return dataclasses.replace(_sofar_12(), restart_buffer_scale=0.25)


def _sofar_14() -> StackConfig:
    base = _sofar_13()
    return dataclasses.replace(base, miqp=dataclasses.replace(base.miqp, daqp_cycle_tol=100))


def _sofar_15() -> StackConfig:
    base = _sofar_13()
    barrier = dataclasses.replace(base.mpc.barrier, heading_sides="toward")
    return dataclasses.replace(base, mpc=dataclasses.replace(base.mpc, barrier=barrier))


def _sofar_16() -> StackConfig:
    base = _sofar_13()
    return dataclasses.replace(base, mpc=dataclasses.replace(base.mpc, qp_solver="daqp", qp_fallback="off"))


def _sofar_17() -> StackConfig:
    base = _sofar_16()
    barrier = dataclasses.replace(base.mpc.barrier, heading_sides="toward")
    return dataclasses.replace(base, mpc=dataclasses.replace(base.mpc, barrier=barrier),
                               miqp=dataclasses.replace(base.miqp, daqp_cycle_tol=100))


DEFAULT_STACK_PRESET = "sofar-17"
"""The versioned name of the default controller: what ``"sofar"`` and an environment without a ``stack`` key
run. Moving it changes the config hash of every default row, so the manifests of the default's tables no
longer match their rows until they are re-made (``tests/eval/test_manifests.py``)."""

_DEFAULT_DOC = """The default controller of every environment, whichever version is current:
now ``"sofar-17"`` (:data:`DEFAULT_STACK_PRESET`), the same value and config hash. Scripts that mean "the
project's controller" name it; a result row records its config hash, so rows of two versions are never mixed
under this name. A fixed version is named by its number (``"sofar-1"``, ``"sofar-4"``, ``"sofar-6"``,
``"sofar-13"``, ``"sofar-17"``)."""

STACK_PRESET_REGISTRY: dict[str, Entry] = {
    "sofar-1": Entry(StackConfig(), """The default controller until ``"sofar-4"`` replaced it (version 1, called
``"sofar"`` in the tables made with it): :class:`StackConfig` as it is, the paper's Algorithm 1 plus the
project's additions (pass or follow, pace-ratio and lateral prediction, footprint-aware edges, consistent
clearances; :mod:`sofar_env.stack`), without the stall fixes. It stalls: a car standing at an angle near an edge
can be left with no plan that moves forward (``docs/decisions/stall-fixes.md``). Kept so that every table made
with it re-makes from its manifest."""),
    "paper": Entry(_paper(), """The paper's Algorithm 1 as written (the *controller* meaning of "paper"), every
addition off:

* ``follow=False``: no pass-or-follow decision; the MIQP always plans a pass of every opponent it sees;
* ``parked_pass=False``: a near-stationary opponent is planned around with the same clearance as any other;
* ``pace_prediction=False``: opponents predicted at constant speed along the track;
* ``lateral_prediction=False``: at a constant lateral offset, whatever lateral rate is sensed;
* ``footprint_edges=False``: the planners' edges are those at the predicted reference point;
* ``miqp.closing_decel=0``: the MIQP's side windows are the plain ``|gap| < safe_lon`` of the paper's eq. (8).

Where the paper leaves a choice open, ``"sofar-1"`` and ``"paper"`` make the same one (MIQP every second step over
76 nodes 0.15 s apart, ``safe_lon`` 8 m, ``safe_lat`` 3.75 m, switching cost 500, clusters of 10 m; one SQP
real-time iteration per step with the DCBF at every stage; soft constraints with L1 + L2 slack; the
velocity-aware barrier ellipse). Episodes, the plant and the opponents are the world's."""),
    "sofar-ends": Entry(_track_rows("ends"), """``"sofar-1"`` with the MPC bounding both ends of the car in its QP
(``mpc.track_rows = "ends"``) instead of tightening its edges by the heading error of the previous plan, a
tightening frozen over the horizon that can leave a car standing at an angle near an edge with no plan that
moves forward (a *stall*). A candidate fix of the stalls, measured against ``"sofar-1"`` in the results."""),
    "sofar-recover": Entry(_track_rows("recoverable"), """``"sofar-ends"`` with room kept for turning back
(``mpc.track_rows = "recoverable"``): the front end's rows bound the largest offset it reaches while the car
turns back to the track's direction at full lock (:mod:`sofar_env.control.mpc.ends`), so a car never stands
turned towards an edge it cannot drive away from. The other candidate fix of the stalls."""),
    "sofar-2": Entry(dataclasses.replace(_track_rows("recoverable"), restart_lateral_weight=15.0,
                                         follow_creep_speed=2.0), """``"sofar-recover"`` plus the restart
mode and the turned-car creep; a candidate default superseded by ``"sofar-3"`` and ``"sofar-4"``. Below 1 m/s
under a free speed reference (until 3 m/s) the MPC tracks the lateral reference with a tenth of its weight
(``restart_lateral_weight`` 15, steering to full lock first when turned beyond ``e*``), and a follow decision
does not brake a car turned more than 0.3 rad to the track below 2 m/s until it is turned less than 0.2 rad
(``follow_creep_speed`` 2). The stall fixes of ``docs/decisions/stall-fixes.md``."""),
    "sofar-3": Entry(dataclasses.replace(StackConfig(), restart_lateral_weight=15.0, follow_creep_speed=2.0,
                                         slow_rows_speed=10.0, slow_rows_exit_speed=12.0), """``"sofar-1"`` plus the
stall fixes of ``"sofar-2"`` with the ends bounded only at low speed; superseded as the candidate by ``"sofar-4"``.
Below 10 m/s (until 12 m/s) a second MPC bounds both ends of the car with room kept for turning back
(``slow_rows_speed``: ``"sofar-recover"``'s rows, which in the dynamic world also raise collisions at racing
speed), with the restart mode and the turned-car creep of ``"sofar-2"``. The stall fixes of
``docs/decisions/stall-fixes.md``."""),
    "sofar-4": Entry(_sofar_4(), """The default controller after ``"sofar-1"``, until ``"sofar-6"`` replaced it
(version 4, called ``"sofar"`` in the tables made with it; kept so that they re-make from their manifests):
``"sofar-3"`` with the slow end rows counting the track's curvature in the room kept for turning back
(``slow_rows_curved``: in a corner a car turned towards the outside edge needs more room to turn back, since the
track turns away while it does). Against ``"sofar-1"``: below 10 m/s (until 12 m/s) a second MPC bounds both ends of
the car with room kept for turning back, a car below 1 m/s restarts with a tenth of the lateral weight, and a follow
decision lets a turned car creep. The stall fixes of ``docs/decisions/stall-fixes.md``."""),
    "sofar-5": Entry(_sofar_5(), """A candidate default superseded by ``"sofar-6"``: ``"sofar-4"`` with DAQP solving
the QPs PIQP fails on (``mpc.qp_fallback = "daqp"``, every MPC of the stack). PIQP can fail on a feasible QP far
outside its soft track rows, such as a start from rest deep inside the dynamic world's 2.2 m track margin, and a
failed QP makes the MPC brake. Measured against ``"sofar-4"`` in ``docs/decisions/qp-backend.md``."""),
    "sofar-6": Entry(_sofar_6(), """The default controller after ``"sofar-4"``, until ``"sofar-13"`` replaced it
(version 6, called ``"sofar"`` in the tables made with it; kept so that they re-make from their manifests):
``"sofar-5"`` with the restart mode's buffer slack (``restart_buffer_edge = 0.05``): while the car restarts from
below 1 m/s (until 3 m/s) a violation of the track margin costs ``mpc.track_buffer_slack`` instead of
``mpc.track_slack`` until the car's side comes within 0.05 m of the edge (0.2 m of the paper worlds' 0.25 m
buffer), so that a car standing inside the margin drives off along it instead of standing (the standing-start
defect of ``docs/decisions/stall-fixes.md``)."""),
    "sofar-7": Entry(_sofar_7(), """A candidate default, not the default: ``"sofar-6"`` with a 6 s horizon in the restart
mode (``restart_horizon = 80`` stages against the MPC's 20, 1.5 s). In a jam (a car stopped a few metres ahead, its
barrier already violated) every forward move first goes deeper into the barrier, and over 1.5 s standing is the
optimum of the MPC's problem; solved to convergence, a 3-6 s horizon drives off at 9 of the 18 probed steps of the
default's stalls (``docs/decisions/stall-fixes.md``, "The remaining stalls probed"). Driving off sooner, it also
collides more on the protocol's dense episodes, superseded as the candidate by ``"sofar-8"``."""),
    "sofar-8": Entry(_sofar_8(), """A candidate default, not the default: ``"sofar-7"`` with the restart mode's barrier
widened with the heading error as in multi-car races (``restart_heading_extent = 2.45`` m, half the car's length).
Driving off over 6 s, a car turned towards a car stopped beside it can sweep its front corner into that car's rear
while the ellipse of aligned cars is still satisfied; the widened ellipse counts the turn. Not adopted: on a seed set
drawn after it was built it stalled 4 times in 480 episodes against 2 of ``"sofar-6"`` (``docs/decisions/stall-fixes.md``,
"A longer horizon in the restart mode")."""),
    "sofar-9": Entry(_sofar_9(), """A candidate default, not the default: ``"sofar-6"`` with the restart mode's buffer
slack at a quarter of its weight (``restart_buffer_scale = 0.25``). At rest on the inside of a tight corner with the
car's end inside the track margin, moving along the corner takes the end deeper into the margin's band, and over the
MPC's 1.5 s ``"sofar-6"`` finds standing for about a second cheaper than starting, at every step again (the free-road
stalls of ``docs/decisions/stall-fixes.md``, "Standing in a tight corner"); the band still ends 0.05 m from the
edge, beyond which the full weight holds."""),
    "sofar-10": Entry(_sofar_10(), """A candidate default, not the default: ``"sofar-6"`` following the queue
(``follow_queue``). When the pass of a car further ahead is blocked and the plan that follows it would have to pass a
nearer car with its clearance violated, ``"sofar-6"`` finds that follow plan no better than the pass and holds the
pass: it passes one car into a chicane whose line the next car holds, and closes on that car's rear (the paper
world's held-out collision of ``docs/decisions/follow-clearance.md``, "Following the queue"). With it the nearer car
is followed too."""),
    "sofar-11": Entry(_sofar_11(), """A candidate default, not the default: ``"sofar-10"`` with the MPC's barrier
widened with the heading error in every world (``mpc.barrier.heading_extent = 2.45`` m, half the car's length), as multi-car
races have it by default. The ellipse of aligned cars certifies no contact only while the cars are aligned; at a slow
turn-in beside a car, the ego turned towards it sweeps its front corner into it while that ellipse still reads
``h`` > 0 (the paper world's protocol collision of ``docs/decisions/follow-clearance.md``, "Turning in beside a
car"). Where the opponents' lateral rates are not sensed (the single-car worlds) only the ego's own turn counts."""),
    "sofar-12": Entry(_sofar_12(), """A candidate default, not the default: ``"sofar-11"`` with the passing planner's
smooth free plan (``miqp.free_plan = "smooth"``). Where the last car of a pass leaves the planner's clearance window,
``"sofar-11"``'s plan is the raceline at once, a step of the lateral reference from the car's offset, which the MPC
takes at its lateral-acceleration limit while braking; on the dynamic world's single-track plant that combination
spins the car or runs it wide (``docs/decisions/dynamic-world-settings.md``, "The departures"). The smooth free
plan is the planner's problem without side constraints: the return keeps the continuity and smoothness of every
other plan."""),
    "sofar-13": Entry(_sofar_13(), """The default controller after ``"sofar-6"``, until ``"sofar-17"`` replaced it
(version 13, called ``"sofar"`` in the tables made with it; kept so that they re-make from their manifests):
``"sofar-12"`` with ``"sofar-9"``'s restart weights (``restart_buffer_scale = 0.25``), so every candidate change since
``"sofar-6"`` in one preset: following the queue, the heading-widened barrier, the smooth free plan and the restart
mode's quarter-weight buffer slack. The restart weights remove the free-road stall of ``"sofar-12"`` in the dynamic
world (a car at rest on the inside of a tight corner finding standing cheaper than starting;
``docs/decisions/stall-fixes.md``, "Standing in a tight corner"). The measurements behind the move:
``docs/decisions/default-controller.md``, "The move to ``"sofar-13"``"."""),
    "sofar-14": Entry(_sofar_14(), """A candidate default, not the default: ``"sofar-13"`` with the passing planner's
DAQP allowed 100 steps without progress instead of 10 (``miqp.daqp_cycle_tol = 100``). With a car alongside over
the whole horizon, as in multi-car races at equal pace, the planner's QP has a clearance row at nearly every node
and DAQP exits with its cycling flag at QPs whose optimum it reaches with the higher limit; the planner then fell
back to its previous plan, about once per 2,700 car-steps of the default's multi-car races. A QP that never reaches
10 is solved to the same bits (``docs/decisions/planner-cycling.md``)."""),
    "sofar-15": Entry(_sofar_15(), """A candidate default, not the default: ``"sofar-13"`` with the barrier widened
only by the turns that bring the ego closer (``mpc.barrier.heading_sides = "toward"``). ``"sofar-13"`` widens it by
every turn of the ego, also when the car is behind another and points away from it, where its front end reaches no
closer: in a parked field it then stands turned away from the car it passes, the widened ellipse holding it back
and the edge it points at holding it in (``docs/decisions/heading-sides.md``)."""),
    "sofar-16": Entry(_sofar_16(), """A candidate default, not the default: ``"sofar-13"`` with the MPC's QP condensed
onto its inputs and solved by DAQP (``mpc.qp_solver = "daqp"``, no fallback backend) instead of PIQP with DAQP as
its fallback. The same problem: DAQP solves it to about 1e-8 where PIQP stops at its tolerances (5e-6 on the first
input, 5e-3 on the plan), never failed on the closed-loop QPs measured, and is now faster per solve; another
floating-point path, so its episodes are compared paired with ``"sofar-13"``'s (``docs/decisions/qp-backend.md``)."""),
    "sofar-17": Entry(_sofar_17(), """The default controller (version 17, also named ``"sofar"``): the three
candidates since ``"sofar-13"`` in one preset, ``"sofar-16"`` (the MPC's QP on DAQP) with ``"sofar-14"``'s planner
cycling limit (``miqp.daqp_cycle_tol = 100``) and ``"sofar-15"``'s barrier widened only by the turns that bring the
ego closer (``mpc.barrier.heading_sides = "toward"``). Each was measured alone against ``"sofar-13"``, then the three
together, paired with ``"sofar-13"`` on the same episodes (``docs/decisions/default-controller.md``, "The move to
``"sofar-17"``")."""),
    "sofar-daqp": Entry(dataclasses.replace(StackConfig(), mpc=dataclasses.replace(StackConfig().mpc,
                                                                                   qp_solver="daqp")),
                        """``"sofar-1"`` with the MPC's QP condensed onto its inputs and solved by DAQP
(``mpc.qp_solver = "daqp"``: one QP solver for both layers) instead of PIQP: the same problem on another
floating-point path, for the comparison of the two backends on the same episodes. Not a default."""),
    "reference-numerics": Entry(_reference_numerics(True), """A **bug-compatible** controller, never a default:
``"paper"`` on the reference's uniform time grid with the low-level MPC replaced by
:class:`~sofar_env.control.refnum.ReferenceNumericsMPC`, which reproduces the numerical defects of the paper's
reference code (``StackConfig.reference_numerics``): phantom opponents 99999 m away in every empty slot, soft
barrier rows bounded at -1e9, no DCBF on the first transition, HPIPM's dense solver with acados' options, a
zero command on a failed solve. It explains the paper's Table I; it is not for racing."""),
    "reference-numerics-no-phantoms": Entry(_reference_numerics(False), """``"reference-numerics"`` with one
defect removed, the phantom opponents (slots without an opponent on the target line get no rows): the control
experiment that attributes a difference to the phantoms."""),
}
"""The controller presets: name -> Entry(StackConfig, doc), in the order of ``STACK_PRESETS``."""
STACK_PRESET_REGISTRY = {"sofar": Entry(STACK_PRESET_REGISTRY[DEFAULT_STACK_PRESET].value, _DEFAULT_DOC),
                         **STACK_PRESET_REGISTRY}  # "sofar" first: the default's value, derived from its version


def default_stack() -> StackConfig:
    """The default controller: the value of preset ``"sofar"`` (= :data:`DEFAULT_STACK_PRESET`), which every
    environment without a ``stack`` key runs."""
    return STACK_PRESET_REGISTRY["sofar"].value


def register_stack_preset(name: str, value: StackConfig, doc: str) -> None:
    """Add the controller preset ``name`` (lower case, not yet registered): afterwards ``stack=name`` selects
    ``value`` in every environment and it is listed in ``STACK_PRESETS``. Raises ``ValueError`` for a name
    in use or not lower case, ``TypeError`` for a value that is not a :class:`StackConfig`."""
    if not isinstance(value, StackConfig):
        raise TypeError(f"a stack preset is a StackConfig, got {type(value).__name__}")
    if not isinstance(name, str) or name != name.strip().lower() or not name:
        raise ValueError(f"a preset name is a non-empty lower-case string without spaces around it, got {name!r}")
    if name in STACK_PRESET_REGISTRY:
        raise ValueError(f"stack preset {name!r} is already registered")
    STACK_PRESET_REGISTRY[name] = Entry(value, doc)


def stack_preset(name: str) -> StackConfig:
    """The controller of preset ``name`` (case and surrounding spaces ignored); ``ValueError`` listing the
    presets for an unknown name."""
    key = name.strip().lower() if isinstance(name, str) else name
    entry = STACK_PRESET_REGISTRY.get(key) if isinstance(key, str) else None
    if entry is None:
        raise ValueError(f"unknown stack preset {name!r}; valid presets: {', '.join(STACK_PRESET_REGISTRY)}")
    return entry.value


# ------------------------------------------------------------------ worlds
_INTERACTIVE: dict[str, Any] = {
    "observation": "extended",
    "race": {
        "sensor": {"enabled": True},
        "opponents": {
            "pace": {"spread": 0.1, "lift_rate": 1.0 / 60.0},
            "lines": {"amplitude": 1.5},
            "defence": {"enabled": True},
        },
    },
}
_DYNAMIC: dict[str, Any] = copy.deepcopy(_INTERACTIVE)
_DYNAMIC["race"].update({
    "plant": "dynamic",
    "dynamic": {"yaw_rate_gain": 2.0},
    "vehicle": {"lat_acc_max": 8.5, "a_min": -7.0},
    "start_speed_fraction": (0.5, 0.7),
})
_DYNAMIC["stack"] = {"speed_factor": 0.7, "mpc": {"track_margin": 2.2, "q": (0.0, 20.0, 0.0, 2.5, 0.0),
                                                  "r": (0.01, 50.0)}}


def _version_2(overrides: dict[str, Any]) -> dict[str, Any]:
    """``overrides`` with the squeeze deadlock removed (``TrafficConfig.yield_to_any = False``)."""
    out = copy.deepcopy(overrides)
    out["race"]["opponents"].setdefault("traffic", {})["yield_to_any"] = False
    return out


WORLD_REGISTRY: dict[str, Entry] = {
    "paper": Entry(World({}), """The paper's world (the *world* meaning of "paper"; the default, the
``SOfAR-<Circuit>-v0`` ids): the MPC's own kinematic bicycle as the plant, exact sensing, opponents on a fixed
lateral offset at a fixed pace ratio rho, blind to the ego. No overrides."""),
    "interactive": Entry(World(_INTERACTIVE), """Opponents that race back (the ``-Interactive-v0`` ids): pace drawn
per car and lifts, own smooth lines, one defensive move per approach; sensing with correlated noise and 0.2 s of
latency; the extended 16-value observation. Kinematic plant."""),
    "dynamic": Entry(World(_DYNAMIC), """The interactive world on the dynamic single-track plant with Pacejka tyres
(the ``-Dynamic-v0`` ids), with what makes the kinematic controller fit it: the car's yaw-rate loop, limits
inside the tyres' grip at the lowest mu, starts at 0.5-0.7 of the profile, and the controller settings
``speed_factor`` 0.7, ``mpc.track_margin`` 2.2 m and calmer steering weights (applied on top of any preset)."""),
    "interactive-2": Entry(World(_version_2(_INTERACTIVE)), """Version 1 of ``"interactive"`` (the
``-Interactive-v1`` ids): a squeezed opponent drops back only for a car or ego level with it, ahead of it or faster
(``race.opponents.traffic.yield_to_any = False``). In ``"interactive"`` a car squeezed by a standing ego a car length
behind it brakes to a standstill and stays squeezed while both stand, which holds the ego until the stall rule ends the
episode (most stalls of the default controller; ``docs/decisions/interactive-opponents.md``)."""),
    "dynamic-2": Entry(World(_version_2(_DYNAMIC)), """Version 1 of ``"dynamic"`` (the ``-Dynamic-v1`` ids): the
dynamic world with the squeezed-opponent rule of ``"interactive-2"``."""),
}
"""The worlds: name -> Entry(World, doc), in the order of ``SCENARIOS``."""


def world(name: str) -> World:
    """The world ``name`` (case and surrounding spaces ignored); ``ValueError`` listing the worlds otherwise."""
    key = name.strip().lower() if isinstance(name, str) else name
    entry = WORLD_REGISTRY.get(key) if isinstance(key, str) else None
    if entry is None:
        raise ValueError(f"unknown scenario {name!r}; valid scenarios: {', '.join(WORLD_REGISTRY)}")
    return entry.value


def world_overrides(name: str) -> dict[str, Any]:
    """The configuration overrides of world ``name`` (a fresh nested dict)."""
    return world(name).as_overrides()


OBSERVATION_LAYOUTS: dict[str, str] = {
    "paper": "The paper's 12 values (the *observation* meaning of \"paper\"; the paper world's default).",
    "extended": "The 12 values plus the two nearest opponents' sensed lateral rates, the heading error and the "
                "smallest barrier value (the interactive worlds' default).",
}
"""The observation layouts of ``EnvConfig.observation`` (:mod:`sofar_env.observation`): name -> doc."""
