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


def make_default(n_agents=4, v2v=False):
    """The new defaults: grid start, pace drawn per episode; ``v2v``: the cars also share their plans."""
    return sofar_env.parallel_env(track="LagunaSeca", n_agents=n_agents, race={**SHORT["race"], "v2v": v2v})


@pytest.mark.parametrize("v2v", [False, True])
def test_parallel_api_on_the_defaults(v2v):
    env = make_default(4, v2v)
    parallel_api_test(env, num_cycles=25)
    env.close()


@pytest.mark.parametrize("v2v", [False, True])
def test_parallel_seed_on_the_defaults(v2v):
    parallel_seed_test(lambda: make_default(3, v2v), num_cycles=10)


def test_pace_is_drawn_per_episode_from_the_seed():
    env, twin = make_default(4), make_default(4)
    env.reset(seed=5)
    first = env.speed_factors
    assert len(first) == 4 and len(set(first)) == 4
    assert all(0.9 <= f <= 1.0 for f in first)
    assert [s.config.speed_factor for s in env.stacks] == list(first)  # the stacks drive at that pace
    twin.reset(seed=5)
    assert twin.speed_factors == first  # same seed: same factors
    env.reset(seed=6)
    assert env.speed_factors != first  # another seed: other factors
    env.reset()
    again = env.speed_factors
    env.reset()
    assert env.speed_factors != again  # every episode draws anew
    env.reset(seed=5)
    assert env.speed_factors == first


def test_pace_range_and_explicit_speed_factors():
    env = sofar_env.parallel_env(track="LagunaSeca", n_agents=3, race={"duration": 2.0, "pace_range": (0.7, 0.75)})
    env.reset(seed=0)
    assert all(0.7 <= f <= 0.75 for f in env.speed_factors)
    fixed = make(3)  # speed_factors=(0.7, 0.85, 0.8): the same in every episode
    for seed in (0, 1):
        fixed.reset(seed=seed)
        assert fixed.speed_factors == (0.7, 0.85, 0.8)
    one = sofar_env.parallel_env(track="LagunaSeca", n_agents=2, speed_factor=0.75, **SHORT)
    one.reset(seed=0)
    assert one.speed_factors == (0.75, 0.75)
    with pytest.raises(ValueError, match="speed_factors"):
        sofar_env.parallel_env(n_agents=2, speed_factors=(0.8, 2.0))
    with pytest.raises(ValueError, match="pace_range"):
        sofar_env.parallel_env(n_agents=2, race={"pace_range": (0.9, 1.6)})


def test_short_race_on_the_defaults_stays_on_the_track():
    """4 cars, 30 s, gamma 0.5, the default grid and pace: every car runs to the end, none off the track."""
    env = sofar_env.parallel_env(track="LagunaSeca", n_agents=4, race={"duration": 30.0})
    env.reset(seed=0)
    steps = 0
    while env.agents:
        obs, rewards, terms, truncs, infos = env.step({a: np.array([0.5], np.float32) for a in env.agents})
        steps += 1
        assert not any(info["off_track"] for info in infos.values()), (steps, infos)
        assert not any(terms.values()), (steps, terms)
    assert steps == 300 and env.race.active.all()
    assert min(env.race.distance) > 30.0 * 0.5 * 19.4  # every car drove (at least half the slowest profile speed)


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
    # the grid: car 1 12 m behind car 0, car 2 24 m: car 2 sees car 1 (12 m) first, then car 0 (24 m)
    gaps2 = (obs["car_2"][3:5] + 1.0) * 110.0 - 20.0
    np.testing.assert_allclose(gaps2, [12.0, 24.0], atol=1e-4)  # float32 observation
    assert infos["car_1"]["nearest_opponent_m"] < 15.0
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
    """Seeded resets of the environment per circuit: no car off the track or touching another
    (the grid itself is checked on 200 seeds per circuit in tests/env/test_race.py)."""
    from sofar_env.multi_agent import parallel_env as make_parallel

    env = make_parallel(track, n_agents=4)
    for seed in range(25):
        _, infos = env.reset(seed=seed)
        race = env.race
        for k in range(race.n_cars):
            assert not race._off_track(k), (track, seed, k)
            assert not race._collides(k), (track, seed, k)
            assert infos[f"car_{k}"]["nearest_opponent_m"] >= 4.0  # 2 x 2 m beside, or 12 m behind
    env.close()

