"""Whom a squeezed opponent drops back for (``TrafficConfig.yield_to_any``).

A car squeezed between its envelope and the keep-clear bounds of a car or ego beside it brakes in the next step
(:mod:`sofar_env.opponents.traffic`). With ``yield_to_any = False`` it does so only when one of those it keeps clear
of is level with it, ahead of it or faster than it: dropping back makes no room for a slower or standing car behind.
"""

from __future__ import annotations

import numpy as np
import pytest

from sofar_env.config import make_env_config
from sofar_env.config_hash import config_hash
from sofar_env.opponents.steering import _yields

# car 0 is squeezed; car 1 (or the ego) is the one it keeps clear of: (gap s_1 - s_0 [m], v_0, v_1) -> yields
CAR_CASES = [
    ("a car ahead", 3.0, 2.0, 2.0, True),
    ("a car level", 0.0, 2.0, 2.0, True),
    ("a faster car behind", -4.0, 2.0, 3.0, True),
    ("a car behind at the same speed", -4.0, 2.0, 2.0, False),
    ("a standing car behind, both standing", -5.0, 0.0, 0.0, False),
    ("a slower car behind", -5.0, 2.0, 0.5, False),
]


@pytest.mark.parametrize("label, gap, v0, v1, expected", CAR_CASES, ids=[c[0] for c in CAR_CASES])
def test_a_squeezed_car_drops_back_only_for_a_car_level_ahead_or_faster(label, gap, v0, v1, expected):
    near = np.array([[False, True], [True, False]])
    gaps = np.array([[0.0, gap], [-gap, 0.0]])
    no_ego = np.zeros((2, 0), dtype=np.bool_)
    assert _yields(0, near, gaps, np.array([v0, v1]), no_ego, no_ego) is expected
    # a car it does not keep clear of never counts
    assert _yields(0, np.zeros((2, 2), dtype=np.bool_), gaps, np.array([v0, v1]), no_ego, no_ego) is False


# (keeps clear of the ego, the ego level with / ahead of the car or faster) -> yields
EGO_CASES = [((True, True), True), ((True, False), False), ((False, True), False)]


@pytest.mark.parametrize("flags, expected", EGO_CASES)
def test_an_ego_counts_only_while_kept_clear_of_and_level_ahead_or_faster(flags, expected):
    near = np.zeros((1, 1), dtype=np.bool_)
    soft, passing = (np.array([[f]], dtype=np.bool_) for f in flags)
    assert _yields(0, near, np.zeros((1, 1)), np.array([2.0]), soft, passing) is expected


def test_the_worlds_of_every_committed_table_keep_their_hash_and_version_2_has_its_own():
    for world in ("interactive", "dynamic"):
        cfg = make_env_config(scenario=world)
        assert cfg.race.opponents.traffic.yield_to_any is True
        two = make_env_config(scenario=f"{world}-2")
        assert two.race.opponents.traffic.yield_to_any is False
        assert config_hash(two) != config_hash(cfg)
        assert config_hash(make_env_config({"race": {"opponents": {"traffic": {"yield_to_any": True}}}},
                                           scenario=world)) == config_hash(cfg)
