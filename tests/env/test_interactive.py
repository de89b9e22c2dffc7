"""The interactive world through the environments: registration, conformance, what is sensed vs judged."""

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from pettingzoo.test import parallel_api_test

import sofar_env  # noqa: F401
from sofar_env.multi_agent import parallel_env
from sofar_env.registration import DYNAMIC_IDS, DYNAMIC_V1_IDS, INTERACTIVE_IDS, INTERACTIVE_V1_IDS
from sofar_env.scenarios import SCENARIOS, scenario_overrides

SHORT = {"race": {"duration": 3.0}}


@pytest.mark.parametrize("ids, scenario", [(INTERACTIVE_IDS, "interactive"), (DYNAMIC_IDS, "dynamic"),
                                           (INTERACTIVE_V1_IDS, "interactive-2"), (DYNAMIC_V1_IDS, "dynamic-2")])
def test_world_ids_are_registered_with_their_scenario(ids, scenario):
    assert len(ids) == 4
    for env_id in ids:
        assert gym.spec(env_id).kwargs["scenario"] == scenario


@pytest.mark.parametrize("env_id", [INTERACTIVE_V1_IDS[2], DYNAMIC_V1_IDS[1]])
def test_version_1_ids_pass_the_checker_and_differ_from_version_0_in_the_squeeze_rule_only(env_id):
    """v1 is v0 with ``race.opponents.traffic.yield_to_any`` off (the squeeze deadlock's fix), nothing else; an id
    without a version is the latest."""
    from dataclasses import asdict

    from gymnasium.utils.env_checker import check_env

    v1 = gym.make(env_id, config=SHORT)
    check_env(v1.unwrapped, skip_render_check=True)
    v0 = gym.make(env_id.replace("-v1", "-v0"), config=SHORT)
    a, b = asdict(v0.unwrapped.config.race), asdict(v1.unwrapped.config.race)
    assert a["opponents"]["traffic"].pop("yield_to_any") is True
    assert b["opponents"]["traffic"].pop("yield_to_any") is False
    assert a == b
    with pytest.warns(UserWarning):
        assert gym.make(env_id[:-3], config=SHORT).spec.id == env_id


def test_scenario_sets_the_world_and_user_keys_win():
    cfg = gym.make("SOfAR-Monza-Interactive-v0").unwrapped.config
    assert cfg.scenario == "interactive"
    assert cfg.race.sensor.enabled and cfg.race.opponents.interactive
    paper = gym.make("SOfAR-Monza-v0").unwrapped.config
    assert paper.scenario == "paper" and not paper.race.sensor.enabled and not paper.race.opponents.interactive
    # the user's keys apply on top of the scenario
    cfg2 = gym.make("SOfAR-Monza-Interactive-v0", config={"race": {"sensor": {"latency_steps": 0}}}).unwrapped.config
    assert cfg2.race.sensor.enabled and cfg2.race.sensor.latency_steps == 0
    with pytest.raises(ValueError, match="valid scenarios: paper, interactive, dynamic, interactive-2, dynamic-2"):
        gym.make("SOfAR-Monza-v0", scenario="mars")
    assert SCENARIOS == ("paper", "interactive", "dynamic", "interactive-2", "dynamic-2") and scenario_overrides("paper") == {}


@pytest.mark.parametrize("env_id", INTERACTIVE_IDS)
def test_gymnasium_check_env_on_interactive_ids(env_id):
    env = gym.make(env_id, config=SHORT)
    check_env(env.unwrapped, skip_render_check=True)
    env.close()


def test_pettingzoo_api_with_the_interactive_scenario():
    parallel_api_test(parallel_env("LagunaSeca", n_agents=2, scenario="interactive", config=SHORT), num_cycles=20)


def test_controller_sees_sensed_rows_while_safety_is_judged_on_the_truth():
    env = gym.make("SOfAR-LagunaSeca-Interactive-v0", rho=0.5).unwrapped
    env.reset(seed=4)
    for _ in range(30):
        env.step(np.array([0.5], np.float32))
    core = env.core
    true_rows, seen = core._opponents[0], core._sensed[0]
    assert seen is not true_rows and seen.shape[1] == 3
    assert not np.array_equal(seen, true_rows)       # noise and latency
    assert np.abs(seen[:, 1] - true_rows[:, 1]).max() < 3.0   # but the same cars, near where they are
    env.close()


@pytest.mark.parametrize("env_id", ["SOfAR-Kentucky-Interactive-v0", "SOfAR-Kentucky-Dynamic-v0"])
def test_interactive_episodes_are_seeded(env_id):
    def run():
        env = gym.make(env_id, rho=0.3, reward_mode="vector")
        obs, _ = env.reset(seed=11)
        out = [obs, [env.unwrapped.race.mu]]  # the dynamic plant's friction draw, too
        for t in range(40):
            obs, r, term, trunc, _ = env.step(np.array([0.2 + 0.02 * t], np.float32))
            out.append(np.concatenate([obs, r]))
            if term or trunc:
                break
        return np.concatenate(out)
    np.testing.assert_array_equal(run(), run())


def test_opponents_move_laterally_in_the_interactive_world():
    env = gym.make("SOfAR-Monza-Interactive-v0", rho=0.5).unwrapped
    env.reset(seed=2)
    n0 = env.race.opponents.n.copy()
    for _ in range(100):
        env.step(np.array([0.5], np.float32))
    assert np.any(np.abs(env.race.opponents.n_dot) > 0) or not np.allclose(env.race.opponents.n, n0)
    env.close()


def test_dynamic_plant_option_drives_the_race():
    """race.plant="dynamic": the Pacejka single-track plant under the kinematic MPC, mu drawn per episode."""
    env = gym.make("SOfAR-LagunaSeca-v0", config={"race": {"plant": "dynamic", "duration": 2.0}}).unwrapped
    env.reset(seed=0)
    lo, hi = env.config.race.dynamic.mu_range
    assert lo <= env.race.mu <= hi and env.race.plant_states.shape == (1, 9)
    s0 = env.race.frenet[0, 0]
    for _ in range(10):
        env.step(np.array([0.5], np.float32))
    assert env.race.frenet[0, 0] != s0 and np.isfinite(env.race.plant_states).all()
    env.close()
