"""The PettingZoo parallel environment: API conformance, seeding, spaces, crashed agents leave."""

import numpy as np
import pytest
from pettingzoo.test import parallel_api_test, parallel_seed_test

import sofar_env
from sofar_env.multi_agent import SOfARParallelEnv

SHORT = {"race": {"duration": 2.0}}  # 20 control steps: the API test reaches the truncation


def make(n_agents=2, **kwargs):
    return sofar_env.parallel_env(track="LagunaSeca", n_agents=n_agents, speed_factors=(0.7, 0.85, 0.8),
                                  **SHORT, **kwargs)


@pytest.mark.parametrize("n_agents", [2, 3])
def test_parallel_api(n_agents):
    env = make(n_agents)
    parallel_api_test(env, num_cycles=25)
    env.close()


def test_parallel_seed():
    # the seed test compares infos exactly: leave out the wall-clock solve times
    parallel_seed_test(lambda: make(2), num_cycles=10)


def test_spaces_are_cached_per_agent():
    env = make(3)
    assert isinstance(env, SOfARParallelEnv)
    for agent in env.possible_agents:
        assert env.observation_space(agent) is env.observation_space(agent)
        assert env.action_space(agent) is env.action_space(agent)
        assert env.action_space(agent).low[0] == np.float32(0.05)


def test_every_car_sees_the_others_as_opponents():
    env = make(3)
    obs, infos = env.reset(seed=0)
    assert env.agents == ["car_0", "car_1", "car_2"]
    # the cars start 40 m apart, car 0 in front: car 2 sees car 1 (40 m) first, then car 0 (80 m)
    gaps2 = (obs["car_2"][3:5] + 1.0) * 110.0 - 20.0
    np.testing.assert_allclose(gaps2, [40.0, 80.0], atol=1e-6)
    assert infos["car_1"]["nearest_opponent_m"] < 45.0
    assert len(env.stacks) == 3 and env.stacks[0] is not env.stacks[1]
    assert [s.config.speed_factor for s in env.stacks] == [0.7, 0.85, 0.8]


def test_crashed_agents_terminate_and_leave():
    env = make(3)
    env.reset(seed=0)
    race = env.race
    # put car 2 onto car 1
    s1 = float(race.frenet[1, 0])
    x, y = race.track.to_cartesian(s1 + 1.0, float(race.frenet[1, 1]))
    race.states[2, :2] = (x, y)
    race.states[2, 2] = race.states[1, 2]
    actions = {a: np.array([0.5], np.float32) for a in env.agents}
    obs, rewards, terms, truncs, infos = env.step(actions)
    assert terms == {"car_0": False, "car_1": True, "car_2": True}
    assert infos["car_1"]["collision"] and infos["car_1"]["is_success"] is False
    assert infos["car_1"]["nearest_opponent_m"] < 5.0  # measured before the crashed cars left
    assert rewards["car_1"] <= -9.0
    assert env.agents == ["car_0"]
    assert not race.active[1] and not race.active[2]
    obs, rewards, terms, truncs, infos = env.step({"car_0": np.array([0.5], np.float32)})
    assert set(obs) == {"car_0"} and not terms["car_0"]


def test_scripted_opponents_are_rejected():
    with pytest.raises(ValueError, match="no scripted opponents"):
        sofar_env.parallel_env(n_agents=2, n_opponents=2)


@pytest.mark.parametrize("track", ["LagunaSeca", "Monza", "Indianapolis", "Kentucky"])
def test_no_car_starts_off_the_track_or_overlapping(track):
    """200 seeded starts per circuit: every car's footprint inside the edges, no two footprints touching."""
    from sofar_env.multi_agent import parallel_env as make_parallel

    env = make_parallel(track, n_agents=4)
    for seed in range(200):
        env.reset(seed=seed)
        race = env.race
        for k in range(race.n_cars):
            assert not race._off_track(k), (track, seed, k)
            assert not race._collides(k), (track, seed, k)
    env.close()
