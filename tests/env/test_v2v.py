"""V2V: the speed handed to a controller reproduces the published plan through its own predictor, cautiously."""

from __future__ import annotations

import numpy as np
import pytest

import sofar_env
from sofar_env.race import RaceConfig
from sofar_env.stack.prediction import OpponentPredictor
from sofar_env.tracks import Track
from sofar_env.v2v import TravelTime, published_advance, speed_for_advance


def test_published_advance_interpolates_and_extends_at_the_last_speed():
    times = np.array([0.0, 0.1, 0.3, 0.5])
    s_pred = 20.0 * times  # 20 m/s
    assert published_advance(times, s_pred, 20.0, elapsed=0.1, horizon=0.4) == pytest.approx(8.0)
    # 0.1 s .. 0.9 s: 0.4 s inside the plan (8 m), then 0.4 s at the last speed 30 m/s (12 m)
    assert published_advance(times, s_pred, 30.0, elapsed=0.1, horizon=0.8) == pytest.approx(8.0 + 12.0)
    assert published_advance(times, -s_pred, 0.0, 0.1, 0.4) == 0.0  # never backwards


@pytest.mark.parametrize("s0", [100.0, 1500.0, 3550.0])
@pytest.mark.parametrize("advance", [10.0, 45.0])
def test_the_controllers_predictor_reaches_the_published_arc_length(s0, advance):
    track = Track.load("Monza")
    horizon = 1.5
    for pace in (False, True):
        v = speed_for_advance(TravelTime(track) if pace else None, s0, advance, horizon)
        predicted = OpponentPredictor(track, pace_ratio=pace)(s0, np.array([[0.0, 0.0, v]]), np.array([horizon]))
        assert predicted[0, 0] == pytest.approx(advance, abs=1e-6), pace


def test_v2v_must_be_a_bool():
    with pytest.raises(ValueError, match="race.v2v"):
        RaceConfig(v2v="yes")


def test_with_v2v_the_controllers_get_the_published_speeds():
    env = sofar_env.parallel_env(track="LagunaSeca", n_agents=3, race={"duration": 2.0, "v2v": True},
                                 speed_factors=(0.9, 0.95, 1.0))
    env.reset(seed=0)
    core = env.core
    first = core._v2v_rows()
    assert all(a is b for a, b in zip(first, core._sensed_rows))  # nothing published before the first step
    env.step({a: np.array([0.5], np.float32) for a in env.agents})
    rows = core._v2v_rows()
    changed = 0
    for car in range(3):
        np.testing.assert_array_equal(rows[car][:, :2], core._sensed[car][:, :2])  # positions as sensed
        ahead = np.array([core.track.gap(s, core.race.frenet[car, 0]) >= 0 for s in rows[car][:, 0]])
        sensed = core._sensed[car][:, 2]
        assert np.all(rows[car][ahead, 2] <= sensed[ahead]) and np.all(rows[car][~ahead, 2] >= sensed[~ahead])
        changed += int(np.sum(rows[car][:, 2] != sensed))
    assert changed > 0  # the plans told something the sensed speeds did not
    off = sofar_env.parallel_env(track="LagunaSeca", n_agents=3, race={"duration": 2.0},
                                 speed_factors=(0.9, 0.95, 1.0))
    off.reset(seed=0)
    assert off.core._travel_time is None  # the default: prediction from sensing only
