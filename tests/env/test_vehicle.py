"""Analytic checks of the vehicle model and the plant."""

import math

import casadi as ca
import numpy as np
import pytest

from sofar_env.vehicle import (
    AV21,
    Plant,
    VehicleParams,
    casadi_cartesian_dynamics,
    casadi_frenet_dynamics,
    cartesian_rhs,
    frenet_rhs,
    lateral_acceleration,
)


def test_parameters_are_the_av21():
    assert AV21.wheelbase == pytest.approx(2.9718)
    assert AV21.lr == pytest.approx(1.2933)
    assert (AV21.a_min, AV21.a_max) == (-10.0, 3.0)
    assert AV21.steer_rate_max == 0.35 and AV21.steer_max == 0.25 and AV21.lat_acc_max == 15.0
    with pytest.raises(ValueError):
        VehicleParams(lr=5.0)
    with pytest.raises(Exception):
        AV21.wheelbase = 3.0  # frozen


def test_straight_road_constant_speed_travels_v_times_t():
    plant = Plant(AV21, dt=0.1)
    x = np.array([0.0, 0.0, 0.3, 20.0, 0.0])
    for _ in range(20):
        x = plant.step(x, (0.0, 0.0))
    assert x[0] == pytest.approx(40.0 * math.cos(0.3), abs=1e-9)
    assert x[1] == pytest.approx(40.0 * math.sin(0.3), abs=1e-9)
    assert x[3] == pytest.approx(20.0)


def test_constant_acceleration_matches_kinematics():
    plant = Plant(AV21, dt=0.1)
    x = np.array([0.0, 0.0, 0.0, 10.0, 0.0])
    for _ in range(10):
        x = plant.step(x, (2.0, 0.0))
    assert x[3] == pytest.approx(12.0)
    assert x[0] == pytest.approx(10.0 + 0.5 * 2.0, abs=1e-9)


def test_plant_enforces_actuator_limits():
    plant = Plant(AV21, dt=0.1)
    x = np.array([0.0, 0.0, 0.0, 5.0, 0.0])
    x1 = plant.step(x, (50.0, 5.0))
    assert x1[3] == pytest.approx(5.0 + AV21.a_max * 0.1)
    assert x1[4] == pytest.approx(AV21.steer_rate_max * 0.1)
    for _ in range(30):
        x1 = plant.step(x1, (-50.0, 5.0))
    assert x1[3] == 0.0  # no reversing
    assert x1[4] == pytest.approx(AV21.steer_max)
    with pytest.raises(ValueError):
        plant.step(x, (float("nan"), 0.0))


def test_steady_turn_radius_matches_the_bicycle_with_slip():
    # yaw rate v/L cos(beta) tan(delta) at constant speed: a circle of radius L / (cos(beta) tan(delta))
    delta = 0.05
    beta = math.atan(AV21.lr / AV21.wheelbase * math.tan(delta))
    radius = AV21.wheelbase / (math.cos(beta) * math.tan(delta))
    plant = Plant(AV21, dt=0.1)
    x = np.array([0.0, 0.0, 0.0, 15.0, delta])
    pts = []
    for _ in range(100):
        x = plant.step(x, (0.0, 0.0))
        pts.append(x[:2])
    pts = np.array(pts)
    # fit a circle through the trajectory
    A = np.column_stack([2 * pts[:, 0], 2 * pts[:, 1], np.ones(len(pts))])
    b = (pts ** 2).sum(1)
    cx, cy, c = np.linalg.lstsq(A, b, rcond=None)[0]
    r_fit = math.sqrt(c + cx ** 2 + cy ** 2)
    assert r_fit == pytest.approx(radius, rel=1e-6)
    assert lateral_acceleration(15.0, delta, AV21) == pytest.approx(15.0 ** 2 / radius)


def test_casadi_and_numeric_models_are_the_same_equations():
    rng = np.random.default_rng(0)
    fc = casadi_cartesian_dynamics(AV21)
    ff = casadi_frenet_dynamics(AV21)
    for _ in range(5):
        x = rng.normal(size=5) * [10, 10, 1, 10, 0.1] + [0, 0, 0, 30, 0]
        u = rng.normal(size=2)
        kappa = rng.normal() * 0.01
        np.testing.assert_allclose(np.array(fc(x, u)).ravel(), cartesian_rhs(x, u, AV21), rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(np.array(ff(x, u, kappa)).ravel(), frenet_rhs(x, u, kappa, AV21), rtol=1e-12, atol=1e-12)


def test_frenet_model_on_a_straight_line_equals_the_cartesian_model():
    # with kappa = 0 the Frenet frame is the x axis: s = x, n = y, e = psi
    F = casadi_frenet_dynamics(AV21, dt=0.1, substeps=4)
    plant = Plant(AV21, dt=0.1)
    x_c = np.array([0.0, 0.5, 0.02, 25.0, 0.01])
    x_f = np.array([0.0, 0.5, 0.02, 25.0, 0.01])
    for _ in range(10):
        x_c = plant.step(x_c, (1.0, -0.02))
        x_f = np.array(F(x_f, [1.0, -0.02], 0.0)).ravel()
    np.testing.assert_allclose(x_f, x_c, atol=1e-9)
