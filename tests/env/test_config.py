"""Configuration: kwargs / mappings validated into frozen dataclasses, unknown keys rejected."""

import dataclasses

import gymnasium as gym
import pytest

import sofar_env  # noqa: F401
from sofar_env.config import ConfigError, EnvConfig, RewardWeights, make_env_config
from sofar_env.env import SOfARRaceEnv
from sofar_env.race import RaceConfig


def test_defaults():
    cfg = make_env_config()
    assert isinstance(cfg, EnvConfig)
    assert (cfg.track, cfg.n_opponents, cfg.rho, cfg.decision_interval, cfg.reward_mode) == (
        "LagunaSeca", 4, 0.3, 1, "scalar")
    assert cfg.race.max_steps == 2000
    assert tuple(cfg.reward_weights.as_array()) == (10.0, 1.0, 0.05, 0.5, 0.1)
    with pytest.raises(dataclasses.FrozenInstanceError):
        cfg.decision_interval = 3


def test_shortcuts_land_in_the_sub_configs_and_kwargs_win():
    cfg = make_env_config({"rho": 0.5, "n_opponents": 2, "offsets": [1.0, -1.0], "speed_factor": 0.9,
                           "use_miqp": False, "race": {"duration": 30.0, "opponents": {"gaps": [50, 90]}},
                           "reward_weights": {"safety": 20.0}}, rho=0.65, decision_interval=3)
    assert cfg.race.opponents.rho == 0.65 and cfg.rho == 0.65
    assert cfg.race.opponents.n_opponents == 2
    assert cfg.race.opponents.offsets == (1.0, -1.0)
    assert cfg.race.opponents.gaps == (50, 90)
    assert cfg.stack.speed_factor == 0.9 and cfg.stack.use_miqp is False
    assert cfg.race.duration == 30.0 and cfg.race.max_steps == 300
    assert cfg.reward_weights == RewardWeights(safety=20.0)
    assert cfg.decision_interval == 3


def test_sub_config_objects_are_accepted():
    race = RaceConfig(duration=10.0)
    cfg = make_env_config(race=race, rho=0.1)
    assert cfg.race.duration == 10.0 and cfg.rho == 0.1


@pytest.mark.parametrize("bad", [
    {"bogus": 1},
    {"race": {"bogus": 1}},
    {"race": {"opponents": {"speed": 3}}},
    {"stack": {"mpc": {"horizn": 10}}},
    {"reward_weights": {"speed": 1.0}},
])
def test_unknown_keys_are_rejected_with_their_path(bad):
    with pytest.raises(ConfigError) as exc:
        make_env_config(bad)
    assert "unknown configuration key" in str(exc.value)
    assert isinstance(exc.value, ValueError)


@pytest.mark.parametrize("bad", [
    {"decision_interval": 0}, {"reward_mode": "both"}, {"rho": -0.1}, {"race": {"duration": -1.0}},
    {"speed_factor": 3.0}, {"race": 5},
])
def test_invalid_values_are_rejected(bad):
    with pytest.raises(ValueError):
        make_env_config(bad)


def test_env_and_make_reject_unknown_keys():
    with pytest.raises(ValueError, match="unknown configuration key 'bogus'"):
        SOfARRaceEnv(bogus=1)
    with pytest.raises(ValueError, match="race.bogus"):
        gym.make("SOfAR-LagunaSeca-v0", config={"race": {"bogus": 1}})


def test_unknown_top_level_key_lists_the_fields_and_the_shortcuts():
    with pytest.raises(ConfigError) as exc:
        make_env_config({"rho": 0.4, "n_opponent": 2})
    text = str(exc.value)
    assert "unknown configuration key 'n_opponent'" in text
    for key in ("decision_interval", "race", "stack", "track", "reward_mode"):
        assert key in text.split("shortcuts:")[0]
    for shortcut in ("n_opponents (= race.opponents.n_opponents)", "rho (= race.opponents.rho)", "offsets",
                     "speed_factor (= stack.speed_factor)", "use_miqp"):
        assert shortcut in text.split("shortcuts:")[1]
