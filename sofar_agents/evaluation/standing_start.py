"""Can a controller drive off from rest near an edge? The standing-start probe.

A car that stops near an edge (behind a car it followed, after a slow corner) must be able to start again: a
controller that cannot leaves it standing until the stall rule ends the episode. Episodes find such states
rarely (a few stalls in a thousand); this probe places them on purpose. On an empty track (no opponents), the
ego stands at ``count`` arc lengths spread evenly over the lap, on either side, with its side ``clearance``
metres from the edge, straight to the track and with straight wheels; the controller drives it with a fixed
gamma for ``duration`` seconds of simulated time. A placement *drove off* when the car gained at least
``min_distance`` metres of arc length without leaving the track.

Each row records the placement, the controller preset, the configuration hash of its environment (the world's
settings with that preset) and the outcome. The environment is the registered one (``SOfAR-<Circuit>-v0`` with
``config={"stack": ..., "scenario": ...}``), reset without opponents; the car is then placed with
:func:`place_at_rest`, before the first step, while the controller has no plan yet.
"""

from __future__ import annotations

import csv
import io
import math
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["Placement", "StartRow", "placements", "place_at_rest", "drive_off", "run_probe", "format_probe",
           "ROW_COLUMNS", "CSV_NAME", "write_probe", "probe_row_id", "run_probe_manifest"]

CSV_NAME = "standing_start.csv"
"""The probe's rows in its folder (its report: ``standing_start.md``)."""


@dataclass(frozen=True)
class Placement:
    """Where the ego stands: arc length and lateral offset [m], heading error [rad], steering angle [rad]."""

    s: float
    n: float
    side: str
    """``"left"`` or ``"right"``: the edge it stands near."""
    clearance: float
    """Distance from its side to that edge [m]."""
    e: float = 0.0
    delta: float = 0.0


@dataclass(frozen=True)
class StartRow:
    """One placement driven by one controller."""

    stack: str
    config_hash: str
    scenario: str
    track: str
    s: float
    n: float
    side: str
    clearance: float
    distance: float
    """Arc length gained in the run [m]."""
    speed: float
    """Speed at the end [m/s]."""
    off_track: bool
    mpc_failures: int
    """MPC solves that failed (the stack's fallback drove those steps)."""
    drove_off: bool


ROW_COLUMNS = tuple(StartRow.__dataclass_fields__)
"""Columns of the probe's CSV, in order."""


def placements(track, count: int, clearances: Sequence[float], vehicle) -> list[Placement]:
    """``count`` arc lengths evenly spread over the lap (from 0), each on both sides at each clearance [m]: the
    car, straight to the track, stands with its side that far from the edge where the edge comes closest along its
    length (``vehicle``: :class:`~sofar_env.vehicle.VehicleParams`; the edge is sampled at 9 points from the rear
    end to the front end). A side with no room for the car at that clearance is skipped."""
    if count < 1:
        raise ValueError(f"count must be >= 1, got {count!r}")
    half = 0.5 * vehicle.width
    along = np.linspace(-(vehicle.length - vehicle.cg_to_front), vehicle.cg_to_front, 9)
    out = []
    for s in np.linspace(0.0, float(track.length), int(count), endpoint=False):
        s = float(s)
        left = float(np.min(track.width_left(s + along)))
        right = float(np.min(track.width_right(s + along)))
        for clearance in clearances:
            if not (math.isfinite(clearance) and clearance >= 0.0):
                raise ValueError(f"clearances must be finite and >= 0 [m], got {clearance!r}")
            n_left, n_right = left - half - clearance, -(right - half - clearance)
            if n_left > n_right:  # room for the car between the two edges
                out.append(Placement(s, n_left, "left", float(clearance)))
                out.append(Placement(s, n_right, "right", float(clearance)))
    return out


def place_at_rest(race, placement: Placement) -> None:
    """Put controlled car 0 of ``race`` (a single-car race, just reset) at ``placement``, at rest: its Frenet and
    Cartesian state and, on the dynamic plant, its full plant state. ``ValueError`` (nothing changed) for a race
    with other controlled cars or a steering angle beyond the lock."""
    if race.n_cars != 1:
        raise ValueError(f"place_at_rest takes a single-car race, got {race.n_cars} cars")
    steer_max = race.config.vehicle.steer_max
    if not abs(placement.delta) <= steer_max:
        raise ValueError(f"placement.delta must lie within the lock +-{steer_max} rad, got {placement.delta!r}")
    track = race.track
    s = float(track.wrap(placement.s))
    x, y = (float(v) for v in track.to_cartesian(s, placement.n))
    psi = float(track.heading(s)) + placement.e
    race.states[0] = (x, y, psi, 0.0, placement.delta)
    race.frenet[0] = (s, placement.n, placement.e, 0.0, placement.delta)
    if race.dynamic:
        race.plant_states[0] = race.plant.initial_state(x, y, psi, 0.0, placement.delta)


def drive_off(env, placement: Placement, gamma: float, duration: float, min_distance: float,
              seed: int = 0) -> tuple[float, float, bool, int, bool]:
    """Reset ``env`` (a registered SOfAR environment) without opponents, place the ego at ``placement`` and drive
    it with ``gamma`` for ``duration`` seconds of simulated time (or until the episode ends); returns (arc length
    gained [m], final speed [m/s], off track, failed MPC solves, drove off)."""
    env.reset(seed=seed, options={"n_opponents": 0})
    race = env.unwrapped.race
    place_at_rest(race, placement)
    s0 = float(race.frenet[0, 0])
    action = np.array([gamma], dtype=np.float32)
    off = False
    while race.time < duration - 1e-9:
        _, _, terminated, truncated, info = env.step(action)
        off |= bool(info["off_track"])
        if terminated or truncated:
            break
    distance = float(race.track.gap(float(race.frenet[0, 0]), s0))
    failures = int(env.unwrapped.stack.counters["mpc_failures"])
    return distance, float(race.frenet[0, 3]), off, failures, (distance >= min_distance and not off)


def run_probe(tracks: Iterable[str], stacks: Iterable[str], scenario: str = "paper", count: int = 25,
              clearances: Sequence[float] = (0.5, 0.3, 0.15), gamma: float = 0.5, duration: float = 8.0,
              min_distance: float = 5.0, keep: Callable[[str, Placement], bool] | None = None) -> list[StartRow]:
    """Every placement of every circuit driven by every controller preset (module docstring); with ``keep``, only
    the placements ``keep(circuit, placement)`` accepts (for re-making committed rows)."""
    import gymnasium as gym

    import sofar_env  # noqa: F401  (registers the ids)
    from sofar_env.config_hash import config_hash

    rows = []
    for track in tracks:
        for stack in stacks:
            env = gym.make(f"SOfAR-{track}-v0", config={"stack": stack, "scenario": scenario})
            try:
                env.reset(seed=0, options={"n_opponents": 0})
                u = env.unwrapped
                h = config_hash(u.config)
                for p in placements(u.track, count, clearances, u.race.config.vehicle):
                    if keep is not None and not keep(track, p):
                        continue
                    dist, speed, off, failures, ok = drive_off(env, p, gamma, duration, min_distance)
                    rows.append(StartRow(stack, h, scenario, track, p.s, p.n, p.side, p.clearance, dist, speed,
                                         off, failures, ok))
            finally:
                env.close()
    return rows


def format_probe(rows: Sequence[StartRow]) -> str:
    """Markdown: per controller and clearance, the placements it drove off from (of all), then the ones it did
    not, per circuit."""
    stacks = list(dict.fromkeys(r.stack for r in rows))
    clearances = sorted({r.clearance for r in rows}, reverse=True)
    head = "| controller | config hash | " + " | ".join(f"{c:g} m from the edge" for c in clearances) + " | all |"
    lines = [head, "|" + "---|" * (len(clearances) + 3)]
    for stack in stacks:
        mine = [r for r in rows if r.stack == stack]
        cells = []
        for c in clearances + [None]:
            sel = [r for r in mine if c is None or r.clearance == c]
            cells.append(f"{sum(r.drove_off for r in sel)} of {len(sel)}")
        lines.append(f"| `{stack}` | {mine[0].config_hash} | " + " | ".join(cells) + " |")
    lines += ["", "Placements a controller did not drive off from (arc length, offset, clearance; gained distance; "
              "failed MPC solves of the run, where any):", ""]
    for stack in stacks:
        bad = [r for r in rows if r.stack == stack and not r.drove_off]
        stuck = sum(1 for r in bad if r.mpc_failures)
        head = f"- `{stack}` ({stuck} of {len(bad)} with failed MPC solves)" if bad else f"- `{stack}`"
        text = "; ".join(f"{r.track} s {r.s:.0f} n {r.n:+.2f} ({r.clearance:g} m){' off track' if r.off_track else ''}"
                         f" {r.distance:.1f} m" + (f", {r.mpc_failures} failed" if r.mpc_failures else "")
                         for r in bad) or "none"
        lines.append(f"{head}: {text}")
    return "\n".join(lines) + "\n"


def row_dict(row: StartRow) -> dict:
    """The CSV row of ``row`` (:data:`ROW_COLUMNS`)."""
    return asdict(row)


def write_probe(out: str | Path, rows: Sequence[StartRow], title: str, footer: str) -> str:
    """Write ``rows`` to ``out/standing_start.csv`` and the report (``title``, :func:`format_probe`, ``footer``) to
    ``out/standing_start.md``, each atomically; returns the report."""
    from sofar_agents.evaluation.files import write_text_atomic

    out = Path(out)
    buf = io.StringIO()
    writer = csv.DictWriter(buf, ROW_COLUMNS, lineterminator="\n")
    writer.writeheader()
    writer.writerows(row_dict(r) for r in rows)
    write_text_atomic(out / CSV_NAME, buf.getvalue())
    text = f"# {title}\n\n" + format_probe(rows) + f"\n{footer}\n"
    write_text_atomic(out / "standing_start.md", text)
    return text


def probe_row_id(row: dict[str, Any]) -> tuple:
    """What names a probe row as written in its CSV: ``(track, s, side, clearance)`` (strings)."""
    return str(row["track"]), str(row["s"]), str(row["side"]), str(row["clearance"])


def run_probe_manifest(m: Any, folder: str | Path, keep: Callable[[tuple], bool] | None = None) -> str:
    """Run the manifest ``m`` of kind ``"standing-start"`` (one controller, ``m.stack``, in ``m.scenario``) into
    ``folder``; with ``keep``, only the placements whose :func:`probe_row_id` it accepts. Returns the report.
    The probe is deterministic and takes about a minute per controller: it is run whole, not resumed."""
    (gamma,) = m.gammas or (0.5,)
    filt = None if keep is None else (lambda track, p: keep(probe_row_id({"track": track, "s": p.s, "side": p.side,
                                                                          "clearance": p.clearance})))
    t0 = time.perf_counter()
    rows = run_probe(m.tracks, [m.stack], m.scenario, m.count, m.clearances, gamma, m.drive_time, m.min_distance,
                     keep=filt)
    title = (f"Standing starts near an edge ({m.scenario} world, gamma {gamma:g}, {m.drive_time:g} s, drove off: "
             f"{m.min_distance:g} m gained on the track)")
    footer = (f"{len(rows)} runs in {time.perf_counter() - t0:.0f} s in one process. Command: "
              f"`python eval/manifest.py run {m.name}`")
    return write_probe(folder, rows, title, footer)
