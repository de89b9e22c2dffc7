"""The standing-start probe: placements at a given distance from the edge, placing a car at rest, driving off."""

from __future__ import annotations

import dataclasses

import gymnasium as gym
import numpy as np
import pytest

import sofar_env  # noqa: F401  (registers the ids)
from sofar_agents.evaluation.standing_start import (ROW_COLUMNS, Placement, StartRow, drive_off, format_probe,
                                                    place_at_rest, placements)
from sofar_env.race import Race, RaceConfig
from sofar_env.tracks import Track
from sofar_env.vehicle import VehicleParams

VEH = VehicleParams()


@pytest.fixture(scope="module")
def laguna():
    return Track.load("LagunaSeca")


def _corner_room(track, p: Placement) -> float:
    """Smallest distance of the car's side to the edge on its side, along the car (sampled finely)."""
    along = np.linspace(-(VEH.length - VEH.cg_to_front), VEH.cg_to_front, 41)
    if p.side == "left":
        return float(np.min(track.width_left(p.s + along))) - (p.n + 0.5 * VEH.width)
    return float(np.min(track.width_right(p.s + along))) + (p.n - 0.5 * VEH.width)


def test_placements_stand_at_the_clearance_on_both_sides(laguna):
    found = placements(laguna, 10, [0.5, 0.15], VEH)
    assert {p.side for p in found} == {"left", "right"} and {p.clearance for p in found} == {0.5, 0.15}
    assert len({p.s for p in found}) == 10 and found[0].s == 0.0
    for p in found:
        assert p.e == 0.0 and p.delta == 0.0
        assert (p.n > 0) == (p.side == "left")
        # the narrowest edge along the car sets the offset: sampled finely, the room is the clearance to 2 cm
        assert _corner_room(laguna, p) == pytest.approx(p.clearance, abs=0.02), p


@pytest.mark.parametrize("count, clearances, match", [
    (0, [0.3], "count"), (5, [-0.1], "clearances"), (5, [float("nan")], "clearances"),
])
def test_bad_probe_settings_are_refused(laguna, count, clearances, match):
    with pytest.raises(ValueError, match=match):
        placements(laguna, count, clearances, VEH)


def test_a_placed_car_stands_where_it_was_put_and_bad_placements_change_nothing(laguna):
    race = Race(laguna, RaceConfig(random_start=False))
    race.reset(np.random.default_rng(0), n_opponents=0)
    p = Placement(1005.0, -0.9, "right", 0.15, e=0.05, delta=-0.1)
    place_at_rest(race, p)
    np.testing.assert_allclose(race.frenet[0], [1005.0, -0.9, 0.05, 0.0, -0.1])
    x, y = laguna.to_cartesian(1005.0, -0.9)
    np.testing.assert_allclose(race.states[0], [x, y, float(laguna.heading(1005.0)) + 0.05, 0.0, -0.1])
    before = race.frenet.copy(), race.states.copy()
    with pytest.raises(ValueError, match="lock"):
        place_at_rest(race, dataclasses.replace(p, delta=0.5))
    two = Race(laguna, RaceConfig(random_start=False), n_cars=2)
    with pytest.raises(ValueError, match="single-car"):
        place_at_rest(two, p)
    np.testing.assert_array_equal(race.frenet, before[0])
    np.testing.assert_array_equal(race.states, before[1])


def _near_the_edge(track) -> Placement:
    """Laguna Seca 1,005 m into the lap, its right side 0.15 m from the right edge, at rest."""
    found = [p for p in placements(track, 25, [0.15], VEH) if abs(p.s - 1005.1) < 1.0 and p.side == "right"]
    assert len(found) == 1
    return found[0]


def _start_near_the_edge(track, stack: str) -> tuple:
    """:func:`drive_off` of ``stack`` from :func:`_near_the_edge` (6 s at gamma 0.5, 5 m to count)."""
    env = gym.make("SOfAR-LagunaSeca-v0", config={"stack": stack})
    try:
        return drive_off(env, _near_the_edge(track), 0.5, duration=6.0, min_distance=5.0)
    finally:
        env.close()


def test_the_former_default_drives_off_from_rest_near_an_edge(laguna):
    distance, speed, off, failures, ok = _start_near_the_edge(laguna, "sofar-1")
    assert ok and not off and distance > 10.0 and speed > 5.0 and failures == 0


def test_the_default_drives_off_from_rest_near_an_edge(laguna):
    """The default (``"sofar-13"``, with ``"sofar-6"``'s restart mode's buffer slack) drives off from the scene
    where ``"sofar-4"`` stands."""
    distance, speed, off, failures, ok = _start_near_the_edge(laguna, "sofar")
    assert ok and not off and distance > 10.0 and failures == 0


def test_the_report_counts_per_controller_and_clearance():
    def row(stack, clearance, ok):
        return StartRow(stack, "abc", "paper", "Monza", 10.0, 1.0, "left", clearance, 20.0 if ok else 0.0, 3.0,
                        False, 0 if ok else 7, ok)

    rows = [row("a", 0.5, True), row("a", 0.15, False), row("b", 0.5, True), row("b", 0.15, True)]
    text = format_probe(rows)
    assert "| `a` | abc | 1 of 1 | 0 of 1 | 1 of 2 |" in text
    assert "| `b` | abc | 1 of 1 | 1 of 1 | 2 of 2 |" in text
    assert "- `a` (1 of 1 with failed MPC solves): Monza s 10 n +1.00 (0.15 m) 0.0 m, 7 failed" in text
    assert "- `b`: none" in text
    assert ROW_COLUMNS[:2] == ("stack", "config_hash") and "drove_off" in ROW_COLUMNS


@pytest.mark.xfail(strict=True, reason="known defect of the former default sofar-4: at rest with its side 0.15 m "
                   "from an edge, the slow end rows (violated from the start) make standing its optimum; "
                   "docs/decisions/stall-fixes.md, 'Standing starts near an edge'")
def test_the_former_default_sofar_4_drives_off_from_rest_near_an_edge(laguna):
    distance, speed, off, failures, ok = _start_near_the_edge(laguna, "sofar-4")
    assert ok and not off and distance > 10.0
