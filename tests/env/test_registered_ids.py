"""The registered ids race what their configuration says: its whole duration (item 12) on its circuit (item 14)."""

import gymnasium as gym
import numpy as np
import pytest

import sofar_env  # noqa: F401  (registers the ids)
from sofar_env.errors import ConfigError
from sofar_env.multi_agent import parallel_env
from sofar_env.registration import CUSTOM_ID, DYNAMIC_IDS, DYNAMIC_V1_IDS, ENV_IDS, INTERACTIVE_IDS, INTERACTIVE_V1_IDS
from sofar_env.tracks import Track

FAST = {"n_opponents": 0, "use_miqp": False}  # a lone car: about 1 ms per step


# ---------------------------------------------------------------------------------------------- item 12
@pytest.mark.parametrize("env_id, config, decisions", [
    ("SOfAR-LagunaSeca-v0", {"race": {"duration": 300.0}}, 3000),
    ("SOfAR-Monza-v0", {"race": {"dt": 0.05, "duration": 100.05}, "stack": {"mpc": {"control_dt": 0.05}}}, 2001),
    ("SOfAR-Kentucky-Interactive-v0", {"race": {"duration": 201.0}}, 2010),
    ("SOfAR-Indianapolis-v0", {"race": {"duration": 250.0}, "decision_interval": 3}, 834),
])
def test_episodes_last_the_configured_duration(env_id, config, decisions):
    """The ids registered a TimeLimit of 2000 steps, which cut these races short without ``is_success``."""
    env = gym.make(env_id, config=config, **FAST)
    env.reset(seed=0)
    for n in range(1, decisions + 10):
        _, _, terminated, truncated, info = env.step(np.array([0.5], np.float32))
        if terminated or truncated:
            break
    race = env.unwrapped.config.race
    assert (n, terminated, truncated) == (decisions, False, True)
    assert info["is_success"] is True
    assert info["sim_time"] == pytest.approx(race.max_steps * race.dt)
    env.close()


@pytest.mark.parametrize("env_id", [*ENV_IDS, *INTERACTIVE_IDS, *DYNAMIC_IDS, *INTERACTIVE_V1_IDS, *DYNAMIC_V1_IDS,
                                    CUSTOM_ID])
def test_no_id_registers_a_step_limit(env_id):
    assert gym.spec(env_id).max_episode_steps is None


# ---------------------------------------------------------------------------------------------- item 14
@pytest.mark.parametrize("env_id, kwargs, words", [
    ("SOfAR-LagunaSeca-v0", {"config": {"track": "Monza"}}, ["config['track'] = 'Monza'", "track='LagunaSeca'"]),
    ("SOfAR-Monza-Interactive-v0", {"config": {"track": "Indianapolis"}}, ["'Indianapolis'", "track='Monza'"]),
    ("SOfAR-Kentucky-Dynamic-v0", {"config": {"track": "LS"}}, ["'LS'", "track='Kentucky'"]),
    ("SOfAR-LagunaSeca-v0", {"config": {"track": "Bogus"}}, ["unknown track 'Bogus'", "valid names", "Monza"]),
    ("SOfAR-LagunaSeca-v0", {"config": {"track": 7}}, ["config['track']", "circuit name"]),
    ("SOfAR-LagunaSeca-v0", {"track": "Bogus"}, ["unknown track 'Bogus'", "valid names", "Kentucky"]),
    ("SOfAR-LagunaSeca-v0", {"config": {"track": "no/such/folder"}}, ["'no/such/folder' is not a circuit folder"]),
    ("SOfAR-LagunaSeca-Interactive-v0", {"config": {"scenario": "paper"}}, ["config['scenario']", "'interactive'"]),
])
def test_a_conflicting_or_unknown_track_is_refused_at_make(env_id, kwargs, words):
    """``config={"track": "Monza"}`` on a Laguna Seca id raced Laguna Seca, and so did an unknown name."""
    with pytest.raises(ConfigError) as info:
        gym.make(env_id, **kwargs)
    for w in words:
        assert w in str(info.value), str(info.value)


@pytest.mark.parametrize("env_id, kwargs, circuit", [
    ("SOfAR-LagunaSeca-v0", {"config": {"track": "LS"}}, "LagunaSeca"),  # the same circuit by its alias
    ("SOfAR-LagunaSeca-v0", {"config": {"track": "lagunaseca"}}, "LagunaSeca"),
    ("SOfAR-LagunaSeca-v0", {"track": "Monza"}, "Monza"),  # the keyword replaces the id's circuit
    ("SOfAR-LagunaSeca-v0", {"track": "Monza", "config": {"track": "monza"}}, "Monza"),
    ("SOfAR-Monza-Interactive-v0", {"config": {"scenario": "Interactive"}}, "Monza"),
])
def test_an_agreeing_track_is_accepted(env_id, kwargs, circuit):
    env = gym.make(env_id, config={"race": {"duration": 0.2}, **kwargs.pop("config", {})}, **kwargs)
    env.reset(seed=0)
    assert env.unwrapped.track.name == circuit
    env.close()


def test_a_track_object_given_twice_must_be_the_same_object():
    monza = Track.load("Monza")
    env = gym.make("SOfAR-LagunaSeca-v0", track=monza, config={"track": monza, "race": {"duration": 0.2}})
    env.reset(seed=0)
    assert env.unwrapped.track is monza
    with pytest.raises(ConfigError, match="conflicts with track="):
        gym.make("SOfAR-LagunaSeca-v0", track=monza, config={"track": "Monza"})


def test_the_pettingzoo_race_refuses_a_conflicting_track_too():
    with pytest.raises(ConfigError, match="config\\['track'\\] = 'Monza'"):
        parallel_env(track="LagunaSeca", n_agents=2, config={"track": "Monza"})
    with pytest.raises(ConfigError, match="valid names"):
        parallel_env(track="Bogus", n_agents=2)
