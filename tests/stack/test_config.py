"""StackConfig validation and the named presets (sofar_env.stack.config)."""

from __future__ import annotations

import dataclasses

import pytest

from sofar_env.configs import EnvConfig
from sofar_env.configs.registry import DEFAULT_STACK_PRESET, default_stack
from sofar_env.stack import STACK_PRESETS, StackConfig, stack_preset


def test_follow_release_slack_is_validated():
    with pytest.raises(ValueError, match="follow_release_slack"):
        StackConfig(follow_release_slack=0.6)
    with pytest.raises(ValueError, match="follow_recheck"):
        StackConfig(follow_recheck=0)


@pytest.mark.parametrize("kwargs, match", [
    ({"speed_factor": 0.0}, "speed_factor"), ({"speed_factor": 1.6}, "speed_factor"),
    ({"miqp_interval": 0}, "miqp_interval"), ({"follow_recheck": 1.5}, "follow_recheck"),
    ({"follow_gap": -1.0}, "follow_gap"), ({"follow_slack": -0.1}, "follow_slack"),
    ({"follow_decel": 0.0}, "follow_decel"), ({"follow_reach_decel": -1.0}, "follow_reach_decel"),
])
def test_invalid_settings_are_rejected(kwargs, match):
    with pytest.raises(ValueError, match=match):
        StackConfig(**kwargs)


def test_the_miqp_side_windows_use_the_barrier_braking_distance():
    cfg = StackConfig()
    assert cfg.miqp.closing_decel == cfg.mpc.barrier.a_brake > 0.0


def test_sofar_preset_is_the_default():
    assert STACK_PRESETS == ("sofar", "sofar-1", "paper", "sofar-ends", "sofar-recover", "sofar-2", "sofar-3",
                             "sofar-4", "sofar-5", "sofar-6", "sofar-7", "sofar-8", "sofar-9", "sofar-10", "sofar-11",
                             "sofar-12", "sofar-13", "sofar-14", "sofar-15", "sofar-16", "sofar-17", "sofar-daqp",
                             "reference-numerics", "reference-numerics-no-phantoms")
    assert DEFAULT_STACK_PRESET == "sofar-17"
    assert stack_preset("sofar") == stack_preset(DEFAULT_STACK_PRESET) == default_stack() == EnvConfig().stack
    assert stack_preset(" SoFAR ") == stack_preset("sofar")
    assert stack_preset("sofar-1") == StackConfig()  # version 1: the default before the stall fixes


def test_the_default_differs_from_version_1_exactly_by_the_stall_fixes_and_the_candidates():
    new, old = stack_preset("sofar"), stack_preset("sofar-1")
    changed = {f.name: getattr(new, f.name) for f in dataclasses.fields(StackConfig)
               if getattr(new, f.name) != getattr(old, f.name)}
    # slow_rows_exit_speed 12 is StackConfig's own, inert while off
    assert changed == {"restart_lateral_weight": 15.0, "follow_creep_speed": 2.0, "slow_rows_speed": 10.0,
                       "slow_rows_curved": True, "restart_buffer_edge": 0.05, "restart_buffer_scale": 0.25,
                       "follow_queue": True, "mpc": new.mpc, "miqp": new.miqp}
    # the MPC's QP on DAQP; the barrier widens with the turns of the heading that bring the ego closer
    assert new.mpc == dataclasses.replace(old.mpc, qp_solver="daqp", barrier=dataclasses.replace(
        old.mpc.barrier, heading_extent=2.45, heading_sides="toward"))
    assert new.miqp == dataclasses.replace(old.miqp, free_plan="smooth", daqp_cycle_tol=100)


def test_paper_preset_switches_off_exactly_the_additions():
    sofar, paper = stack_preset("sofar-1"), stack_preset("paper")
    changed = {f.name for f in dataclasses.fields(StackConfig) if getattr(sofar, f.name) != getattr(paper, f.name)}
    assert changed == {"follow", "parked_pass", "pace_prediction", "lateral_prediction", "footprint_edges", "miqp"}
    assert not paper.follow and not paper.pace_prediction and not paper.footprint_edges
    assert not paper.lateral_prediction
    assert paper.miqp == dataclasses.replace(sofar.miqp, closing_decel=0.0)


@pytest.mark.parametrize("name", ["Paper2026", "", None, 3])
def test_unknown_presets_list_the_valid_ones(name):
    with pytest.raises(ValueError, match="valid presets: sofar, sofar-1, paper"):
        stack_preset(name)
