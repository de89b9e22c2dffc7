"""The interactive world on the dynamic tyre plant (``scenario="dynamic"``): configuration and closed loop."""

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import sofar_env  # noqa: F401
from sofar_env.stack import stack_preset


def test_the_world_is_the_interactive_one_on_the_tyre_plant_with_consistent_limits():
    cfg = gym.make("SOfAR-Monza-Dynamic-v0").unwrapped.config
    inter = gym.make("SOfAR-Monza-Interactive-v0").unwrapped.config
    assert cfg.scenario == "dynamic" and cfg.race.plant == "dynamic" and inter.race.plant == "kinematic"
    assert cfg.race.sensor == inter.race.sensor and cfg.race.opponents == inter.race.opponents
    assert cfg.observation == inter.observation == "extended"
    assert cfg.race.dynamic.yaw_rate_gain > 0
    # the limits sit inside the friction ellipse at the lowest mu without downforce
    dyn, veh = cfg.race.dynamic, cfg.race.vehicle
    mu = dyn.mu_range[0]
    lat_grip, lon_grip = mu * dyn.D_f * dyn.gravity, mu * dyn.D_x * dyn.gravity
    assert (veh.a_min / lon_grip) ** 2 + (veh.lat_acc_max / lat_grip) ** 2 <= 1.0
    # the speed reference (profile built for 15 m/s^2 lateral) fits under the lateral limit
    assert cfg.stack.speed_factor ** 2 * 15.0 <= veh.lat_acc_max
    assert cfg.race.start_speed_fraction[1] <= cfg.stack.speed_factor
    assert cfg.stack.mpc.track_margin > inter.stack.mpc.track_margin


def test_a_named_stack_preset_keeps_the_worlds_stack_settings_and_user_keys_win():
    world = gym.make("SOfAR-Monza-Dynamic-v0").unwrapped.config.stack
    paper = gym.make("SOfAR-Monza-Dynamic-v0", stack="paper").unwrapped.config.stack
    sofar = gym.make("SOfAR-Monza-Dynamic-v0", stack="sofar").unwrapped.config.stack
    assert sofar == world
    assert not paper.follow and not paper.footprint_edges  # the preset's flags ...
    assert paper.speed_factor == world.speed_factor and paper.mpc.q == world.mpc.q  # ... the world's settings
    assert paper.mpc.track_margin == world.mpc.track_margin != stack_preset("paper").mpc.track_margin
    mine = gym.make("SOfAR-Monza-Dynamic-v0", config={"stack": {"speed_factor": 0.6}}).unwrapped.config.stack
    assert mine.speed_factor == 0.6 and mine.mpc.q == world.mpc.q


def test_gymnasium_check_env_on_a_dynamic_id():
    env = gym.make("SOfAR-LagunaSeca-Dynamic-v0", config={"race": {"duration": 3.0}})
    check_env(env.unwrapped, skip_render_check=True)
    env.close()


@pytest.mark.parametrize("track", ["LagunaSeca", "Monza"])
def test_a_lone_car_laps_on_the_tyre_plant_at_the_worlds_pace(track):
    """No opponents, 40 s: the kinematic MPC drives the sliding car without leaving the track, close to
    0.7 of the speed profile, the tyres sliding (side slip != the kinematic bicycle's) but within grip."""
    env = gym.make(f"SOfAR-{track}-Dynamic-v0", n_opponents=0, config={"race": {"duration": 40.0}}).unwrapped
    env.reset(seed=1)
    race, track_ = env.race, env.track
    ratios, lat = [], []
    while True:
        _, _, term, trunc, info = env.step(np.array([0.5], np.float32))
        s, v = race.frenet[0, 0], race.frenet[0, 3]
        ratios.append(v / float(track_.speed(s)))
        lat.append(abs(race.plant.lateral_acceleration(race.plant_states[0])))
        if term or trunc:
            break
    assert info["is_success"] and not info["off_track"] and info["sim_time"] == pytest.approx(40.0)
    assert 0.6 < np.median(ratios[100:]) < 0.75
    # grip at mu with downforce is above 10.9 m/s^2; the car never uses more than the tyres give
    assert max(lat) < race.mu * race.config.dynamic.D_f * 9.81 * 1.3
    env.close()

