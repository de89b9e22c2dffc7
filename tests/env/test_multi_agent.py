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


def test_no_scripted_opponents_unless_asked():
    env = sofar_env.parallel_env(n_agents=2)
    env.reset(seed=0)
    assert env.race.opponents.count == 0 and env.config.n_opponents == 0


@pytest.mark.parametrize("scenario", ["paper", "interactive"])
def test_mixed_field_passes_the_api_test(scenario):
    env = sofar_env.parallel_env(track="LagunaSeca", n_agents=2, n_opponents=2, scenario=scenario, **SHORT)
    parallel_api_test(env, num_cycles=20)
    env.close()


def test_mixed_field_is_seeded():
    parallel_seed_test(lambda: sofar_env.parallel_env(track="LagunaSeca", n_agents=2, n_opponents=2,
                                                      scenario="interactive", **SHORT), num_cycles=10)


@pytest.mark.parametrize("scenario", ["paper", "interactive"])
def test_controlled_cars_pass_scripted_opponents_and_are_credited_once_each(scenario):
    """Two controlled cars behind three slow scripted cars (rho 0.5): every car sees them as opponents,
    passes each of them within 60 s and is credited once per pass; nobody crashes."""
    env = sofar_env.parallel_env(track="LagunaSeca", n_agents=2, n_opponents=3, rho=0.5, scenario=scenario,
                                 speed_factors=(0.95, 0.9))
    obs, infos = env.reset(seed=3)
    race = env.race
    assert race.opponents.count == 3
    assert np.all(race._opp_rel > 0)  # the field starts ahead of the grid
    ids = race.opponent_ids(1)
    assert sorted(ids.tolist()) == [-1, 0, 1, 2]  # car 1 sees car 0 and the three scripted cars
    passes = np.zeros(2, int)
    for _ in range(600):
        obs, rewards, terms, truncs, infos = env.step({a: np.array([0.3], np.float32) for a in env.agents})
        assert not any(terms.values()), {a: (i["collision"], i["off_track"]) for a, i in infos.items()}
        passes = race.overtakes.copy()
    behind = race._opp_rel < -race.config.opponents.overtake_threshold
    assert behind.all()  # both cars are past all three scripted cars ...
    assert np.all(passes >= 3) and np.all(passes <= 4)  # ... credited once each (plus, maybe, each other)
    assert [infos[a]["overtakes"] for a in ("car_0", "car_1")] == passes.tolist()


def test_a_lapped_scripted_opponent_is_passed_again():
    """A scripted car the controlled cars passed long ago comes round again (relative to them) from
    half a lap behind: each car is credited once more when it passes it again."""
    from sofar_env.race import CarEvents

    env = sofar_env.parallel_env(track="LagunaSeca", n_agents=2, n_opponents=1, rho=0.5)
    env.reset(seed=0)
    race, track = env.race, env.race.track
    L = track.length
    cars = race.frenet[:, 0].copy()
    s_opp = float(cars[0]) + 0.5 * L - 3.0  # just under half a lap ahead of car 0
    race.opponents.s[:] = track.wrap(s_opp)
    gaps = np.asarray(track.gap(race.opponents.s[0], cars), float)
    race._opp_rel[:, 0] = np.where(gaps > 0, gaps - L, gaps)  # both cars passed it once already
    race._opp_ahead[:] = False
    credited = np.zeros(2, int)
    while s_opp > cars[1] - 10.0:  # it falls back relative to the cars, 5 m per step, to 10 m behind both
        s_opp -= 5.0
        race.opponents.s[:] = track.wrap(s_opp)
        events = [CarEvents(), CarEvents()]
        race._update_opponent_overtakes(events)
        credited += [e.overtakes for e in events]
    assert credited.tolist() == [1, 1]
    assert np.all(race._opp_rel < 0) and np.all(np.abs(race._opp_rel) < 0.5 * L)


@pytest.mark.parametrize("options, match", [
    ({"n_opponents": -1}, "n_opponents must be a whole number"),
    ({"n_opponents": 1.5}, "n_opponents must be a whole number"),
    ({"n_opponents": 500}, "does not fit on LagunaSeca"),
    ({"rho": 3.0}, "rho must be a number in"),
])
def test_bad_mixed_field_options_raise_and_change_nothing(options, match):
    env = sofar_env.parallel_env(track="LagunaSeca", n_agents=2, n_opponents=1)
    env.reset(seed=0)
    before = env.race.frenet.copy(), env.race.opponents.s.copy()
    with pytest.raises(ValueError, match=match):
        env.reset(seed=1, options=options)
    np.testing.assert_array_equal(env.race.frenet, before[0])
    np.testing.assert_array_equal(env.race.opponents.s, before[1])


def test_side_lock_is_on_in_multi_car_races_only():
    """race.side_lock (6 m) turns on the controllers' MIQP side lock in multi-car races, unless the
    stack sets its own gap; single-car worlds are untouched (their trajectories stay the paper's)."""
    import gymnasium as gym

    env = sofar_env.parallel_env(track="Monza", n_agents=2)
    env.reset(seed=0)
    assert [s.config.miqp.alongside_gap for s in env.stacks] == [6.0, 6.0]
    off = sofar_env.parallel_env(track="Monza", n_agents=2, race={"side_lock": 0.0})
    off.reset(seed=0)
    assert [s.config.miqp.alongside_gap for s in off.stacks] == [0.0, 0.0]
    own = sofar_env.parallel_env(track="Monza", n_agents=2, stack={"miqp": {"alongside_gap": 3.0}})
    own.reset(seed=0)
    assert [s.config.miqp.alongside_gap for s in own.stacks] == [3.0, 3.0]
    single = gym.make("SOfAR-Monza-v0").unwrapped
    single.reset(seed=0)
    assert single.stack.config.miqp.alongside_gap == 0.0
    with pytest.raises(ValueError, match="race.side_lock must be a finite number >= 0"):
        sofar_env.parallel_env(track="Monza", n_agents=2, race={"side_lock": -1.0})


def test_mpc_restart_is_on_in_multi_car_races_only():
    """race.mpc_restart_slack (0.05) turns on the MPC's restart from a cold guess in multi-car races, unless
    the stack sets its own value; single-car worlds are untouched."""
    import math

    import gymnasium as gym

    env = sofar_env.parallel_env(track="Monza", n_agents=2)
    env.reset(seed=0)
    assert [s.config.mpc.restart_slack for s in env.stacks] == [0.05, 0.05]
    off = sofar_env.parallel_env(track="Monza", n_agents=2, race={"mpc_restart_slack": math.inf})
    off.reset(seed=0)
    assert all(math.isinf(s.config.mpc.restart_slack) for s in off.stacks)
    own = sofar_env.parallel_env(track="Monza", n_agents=2, stack={"mpc": {"restart_slack": 0.2}})
    own.reset(seed=0)
    assert [s.config.mpc.restart_slack for s in own.stacks] == [0.2, 0.2]
    single = gym.make("SOfAR-Monza-v0").unwrapped
    single.reset(seed=0)
    assert math.isinf(single.stack.config.mpc.restart_slack)
    for bad in (0.0, -1.0, float("nan")):
        with pytest.raises(ValueError, match="race.mpc_restart_slack must be a number > 0"):
            sofar_env.parallel_env(track="Monza", n_agents=2, race={"mpc_restart_slack": bad})


def test_heading_extent_is_on_in_multi_car_races_only():
    """race.heading_extent (2.45 m) widens each controller's barrier with its heading error in multi-car
    races, unless the stack sets its own value; 0 adds nothing (the controller keeps its own); single-car
    worlds are untouched. The default ``"sofar-17"`` (as ``"sofar-13"``) widens its barrier itself, in every world;
    ``"sofar-6"`` does not."""
    import gymnasium as gym

    env = sofar_env.parallel_env(track="Monza", n_agents=2, stack="sofar-6")
    env.reset(seed=0)
    assert [s.config.mpc.barrier.heading_extent for s in env.stacks] == [2.45, 2.45]
    assert [s.config.mpc.restart_slack for s in env.stacks] == [0.05, 0.05]  # merged with the restart
    off = sofar_env.parallel_env(track="Monza", n_agents=2, stack="sofar-6", race={"heading_extent": 0.0})
    off.reset(seed=0)
    assert [s.config.mpc.barrier.heading_extent for s in off.stacks] == [0.0, 0.0]
    default_off = sofar_env.parallel_env(track="Monza", n_agents=2, race={"heading_extent": 0.0})
    default_off.reset(seed=0)
    assert [s.config.mpc.barrier.heading_extent for s in default_off.stacks] == [2.45, 2.45]  # its own
    own = sofar_env.parallel_env(track="Monza", n_agents=2, stack={"mpc": {"barrier": {"heading_extent": 1.0}}})
    own.reset(seed=0)
    assert [s.config.mpc.barrier.heading_extent for s in own.stacks] == [1.0, 1.0]
    single = gym.make("SOfAR-Monza-v0", stack="sofar-6").unwrapped
    single.reset(seed=0)
    assert single.stack.config.mpc.barrier.heading_extent == 0.0
    default_single = gym.make("SOfAR-Monza-v0").unwrapped
    default_single.reset(seed=0)
    assert default_single.stack.config.mpc.barrier.heading_extent == 2.45
    for bad in (-1.0, float("nan"), float("inf"), "2"):
        with pytest.raises(ValueError, match="race.heading_extent must be a finite number >= 0"):
            sofar_env.parallel_env(track="Monza", n_agents=2, race={"heading_extent": bad})


def _first_collision(env, seed: int, gamma: float, duration: float):
    env.reset(seed=seed)
    action = np.array([gamma], np.float32)
    while env.agents and env.race.time < duration:
        _, _, _, _, infos = env.step({a: action for a in env.agents})
        hit = sorted(a for a, info in infos.items() if info["collision"])
        if hit:
            return round(env.race.time, 1), hit
    return None


def test_mpc_restart_avoids_a_collision_after_a_change_of_side():
    """Indianapolis, a race of the multi-agent table (gamma 0.5): just after the rolling start car 2,
    ahead and to the right, keeps the plan of a pass on the left after its planner switched to
    following; its RTI, linearised along that plan, steers it across car 3 (moving left at ~5 m/s,
    with DCBF slack 0.4) and the two collide at 4.1 s. Restarting from a cold guess when the slack is
    large keeps it on its side: no collision, and the restarts are counted."""
    import math

    seed = 4193085697
    # the cars' lateral rates and the heading-aware barrier (which avoid this collision too) are off, to
    # see the restart alone: "sofar-6", whose own barrier is the aligned one (the default widens it itself)
    off = sofar_env.parallel_env(track="Indianapolis", n_agents=4, stack="sofar-6",
                                 race={"mpc_restart_slack": math.inf, "lateral_rates": "off", "heading_extent": 0.0})
    assert _first_collision(off, seed, 0.5, 5.0) == (4.1, ["car_2", "car_3"])
    on = sofar_env.parallel_env(track="Indianapolis", n_agents=4, stack="sofar-6",
                                race={"lateral_rates": "off", "heading_extent": 0.0})
    assert _first_collision(on, seed, 0.5, 5.0) is None
    assert on.stacks[2].counters["mpc_restarts_taken"] >= 1
    assert all(s.counters["mpc_restarts_taken"] <= s.counters["mpc_restarts"] for s in on.stacks)


def test_lateral_rates_reach_the_controllers_of_a_multi_car_race_only():
    """race.lateral_rates: without a sensor, each controller of a multi-car race gets the other cars' rows
    (s, n, v) plus their true lateral rate v sin(e + beta); "mpc" (the default) keeps them out of the
    passing-side planners; single-car races keep rows of three columns."""
    import math

    import gymnasium as gym

    from sofar_env.vehicle import slip_angle

    env = sofar_env.parallel_env(track="LagunaSeca", n_agents=3)
    env.reset(seed=2)
    for _ in range(15):
        env.step({a: np.array([0.5], np.float32) for a in env.agents})
    race = env.race
    rows = env.core._sensed_rows[0]
    assert rows.shape == (2, 4)
    np.testing.assert_array_equal(rows[:, :3], race.opponent_frenet(0))
    p = env.config.race.vehicle
    expected = [v * math.sin(e + slip_angle(d, p)) for _, _, e, v, d in race.frenet[1:].tolist()]
    np.testing.assert_allclose(rows[:, 3], expected, rtol=0, atol=1e-12)
    assert np.any(np.abs(rows[:, 3]) > 1e-3)  # the cars are moving across somewhat
    assert [s.config.lateral_prediction_plan for s in env.stacks] == [False] * 3
    both = sofar_env.parallel_env(track="LagunaSeca", n_agents=3, race={"lateral_rates": "all"})
    both.reset(seed=2)
    assert both.core._sensed_rows[0].shape == (2, 4)
    assert [s.config.lateral_prediction_plan for s in both.stacks] == [True] * 3
    off = sofar_env.parallel_env(track="LagunaSeca", n_agents=3, race={"lateral_rates": "off"})
    off.reset(seed=2)
    assert off.core._sensed_rows[0].shape == (2, 3)
    with pytest.raises(ValueError, match="race.lateral_rates must be one of 'mpc', 'all', 'off'"):
        sofar_env.parallel_env(track="LagunaSeca", n_agents=3, race={"lateral_rates": True})
    single = gym.make("SOfAR-LagunaSeca-v0").unwrapped
    single.reset(seed=0)
    assert single.core._sensed_rows[0].shape[1] == 3


def test_aec_env_and_raw_env_pass_the_pettingzoo_api_test():
    from pettingzoo import AECEnv
    from pettingzoo.test import api_test
    from pettingzoo.utils.wrappers import OrderEnforcingWrapper

    from sofar_env.multi_agent import env, raw_env

    aec = env(track="LagunaSeca", n_agents=2, **SHORT)
    assert isinstance(aec, OrderEnforcingWrapper)
    api_test(aec, num_cycles=10)
    raw = raw_env(track="LagunaSeca", n_agents=2, **SHORT)
    assert isinstance(raw, AECEnv) and not isinstance(raw, OrderEnforcingWrapper)
    assert raw.possible_agents == ["car_0", "car_1"]
