"""PASTAConfig: validation and the dictionary round trip stored in checkpoints."""

from __future__ import annotations

import json

import pytest

from sofar_agents import PASTAConfig


def test_dict_round_trip_through_json() -> None:
    cfg = PASTAConfig(hidden_sizes=[32, 16], target_kl=0.02, pcgrad=True)
    assert cfg.hidden_sizes == (32, 16)  # lists are normalised to tuples
    d = json.loads(json.dumps(cfg.to_dict()))
    assert d["hidden_sizes"] == [32, 16]
    assert PASTAConfig.from_dict(d) == cfg


def test_unknown_fields_are_refused() -> None:
    with pytest.raises(ValueError, match=r"unknown PASTAConfig fields: \['mu_maximum'\]"):
        PASTAConfig.from_dict({"mu_maximum": 3.0})


@pytest.mark.parametrize("changes, match", [
    ({"n_steps": 0}, "positive"),
    ({"discount": 0.0}, "discount"),
    ({"mu_min": 2.0, "mu_max": 1.0}, "mu_min <= mu_max"),
    ({"maintenance": 1.5}, "maintenance"),
    ({"kappa": 1.0}, "kappa"),
    ({"scalarization": "max"}, "scalarization"),
    ({"preference_sampling": "uniform"}, "preference_sampling"),
    ({"utopia_quantile": 0.4}, "utopia_quantile"),
    ({"conflict_every": 0}, "conflict_every"),
    ({"action_squashing": "tanh"}, "action_squashing"),
])
def test_invalid_values_raise(changes: dict, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        PASTAConfig(**changes)


def test_is_frozen() -> None:
    with pytest.raises(AttributeError):
        PASTAConfig().learning_rate = 1.0  # type: ignore[misc]
