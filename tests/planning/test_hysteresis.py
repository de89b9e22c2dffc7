"""Tests of the side hysteresis of the MIQP (sofar_env.planning.hysteresis)."""

from __future__ import annotations

import numpy as np

from sofar_env.planning import MIQPConfig, PassingSidePlanner
from sofar_env.planning.hysteresis import match_previous_sides, prior_sides

from .instances import CFG, straight


def test_hysteresis_keeps_the_previous_side():
    s, n_ref, n_min, n_max = straight()
    v = s[1] / CFG.node_dt
    # first call: opponent slightly right of centre -> left is cheaper
    opp1 = np.array([[80.0, -0.15, 42.0]])
    # 0.1 s later it sits slightly left of centre -> right would now be cheaper
    progress = 0.1 * v
    opp2 = np.array([[80.0 + (42.0 - v) * 0.1, 0.15, 42.0]])

    fresh = PassingSidePlanner().plan(s, n_ref, n_min, n_max, 0.0, opp2)
    assert fresh.sides[0] == -1

    for cfg, expected in ((MIQPConfig(), +1), (MIQPConfig(w_switch=0.0, w_prev=0.0), -1),
                          (MIQPConfig(w_prev=0.0), +1),
                          (MIQPConfig(solver="enumerate"), +1)):
        planner = PassingSidePlanner(cfg)
        first = planner.plan(s, n_ref, n_min, n_max, 0.0, opp1)
        assert first.sides[0] == +1
        second = planner.plan(s, n_ref, n_min, n_max, float(first.lateral_at(progress)), opp2,
                              progress=progress)
        assert second.sides[0] == expected, cfg


def test_hysteresis_follows_the_car_not_the_row():
    s, n_ref, n_min, n_max = straight()
    far = [150.0, 2.0, 45.0]  # irrelevant car listed first in the second call
    planner = PassingSidePlanner(MIQPConfig(w_prev=0.0))
    first = planner.plan(s, n_ref, n_min, n_max, 0.0, np.array([[80.0, -0.15, 42.0], far]))
    assert first.sides[0] == +1
    second = planner.plan(s, n_ref, n_min, n_max, 0.0, np.array([far, [79.0, 0.15, 42.0]]),
                          progress=5.0)
    assert second.sides[1] == +1  # a fresh planner would pass this one on the right
    fresh = PassingSidePlanner().plan(s, n_ref, n_min, n_max, 0.0, np.array([[79.0, 0.15, 42.0]]))
    assert fresh.sides[0] == -1


def test_hysteresis_ignores_a_respawned_opponent():
    s, n_ref, n_min, n_max = straight()
    planner = PassingSidePlanner(MIQPConfig(w_prev=0.0))
    first = planner.plan(s, n_ref, n_min, n_max, 0.0, np.array([[60.0, -0.15, 42.0]]))
    assert first.sides[0] == +1
    # same row index, but a different car 200 m further ahead: no inherited side
    second = planner.plan(s, n_ref, n_min, n_max, 0.0, np.array([[260.0, 0.15, 42.0]]),
                          progress=5.0)
    fresh = PassingSidePlanner(MIQPConfig(w_prev=0.0)).plan(
        s, n_ref, n_min, n_max, 0.0, np.array([[260.0, 0.15, 42.0]]))
    assert second.sides[0] == fresh.sides[0]


def test_match_follows_the_propagated_car():
    cfg = MIQPConfig()
    s_nodes = 50.0 * cfg.node_dt * np.arange(cfg.nodes)  # ego at 50 m/s
    prev_opp = np.array([[80.0, -0.2, 40.0], [30.0, 2.0, 45.0], [120.0, 0.0, 40.0]])
    prev_sides = np.array([1, -1, 0])  # the third car had no side
    progress = 5.0  # 0.1 s at 50 m/s: the first car is now 80 + 4 - 5 = 79 m ahead
    now = np.array([[79.0, -0.1, 40.0],    # the first car          -> left (1)
                    [29.5, 2.1, 45.0],     # the second car         -> right (0)
                    [120.0 - 1.0, 0.0, 40.0],  # the car without a side -> unknown (-1)
                    [79.0, 4.5, 40.0]])    # abreast of the first, but 4.6 m across -> unknown
    b_prev = match_previous_sides(cfg, s_nodes, progress, now, prev_opp, prev_sides)
    np.testing.assert_array_equal(b_prev, [1, 0, -1, -1])
    np.testing.assert_array_equal(prior_sides(np.array([0, 2, 3, 5]), b_prev, 6), [1, 0, -1, 0, 0, 0])
    # without a previous call nothing is known
    np.testing.assert_array_equal(match_previous_sides(cfg, s_nodes, progress, now, None, None), [-1] * 4)
