"""Tests of the MIQP parameters (sofar_env.planning.config)."""

from __future__ import annotations

import dataclasses

import pytest

from sofar_env.planning import MIQPConfig


@pytest.mark.parametrize("changes", [dict(solver="gurobi"), dict(w_dev=0.0), dict(nodes=1), dict(node_dt=0.0),
                                     dict(safe_lat=-1.0), dict(closing_stride=0), dict(closing_stride=1.5),
                                     dict(window_shape="circle"), dict(alongside_gap=-1.0),
                                     dict(incumbent=1), dict(incumbent="yes")])
def test_invalid_configuration_raises(changes):
    with pytest.raises(ValueError):
        MIQPConfig(**changes)


def test_defaults_are_valid_and_frozen():
    cfg = MIQPConfig()
    assert cfg.nodes >= 2 and cfg.solver == "daqp"
    with pytest.raises(dataclasses.FrozenInstanceError):
        cfg.nodes = 3  # type: ignore[misc]
