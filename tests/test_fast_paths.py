"""The hand-optimised copies in the hot loop give the very same numbers (bit for bit) as the plain forms:
the plant's RK4 step, the footprint corner list, and the planner's time derivative on its node grid
(``sofar_env._gradient.GridGradient``)."""

import math

import numpy as np
import pytest

from sofar_env.geometry import footprint_corner_list, footprint_corners, footprint_radius
from sofar_env.vehicle import AV21, Plant, cartesian_rhs, rk4_step


def reference_plant_step(plant: Plant, x, u) -> np.ndarray:
    """The plant's step written with the generic RK4 of ``cartesian_rhs``."""
    p = plant.params
    a, dd = plant.clip_input(u)
    state = [float(v) for v in x]
    h = plant.dt / plant.substeps
    for _ in range(plant.substeps):
        state = rk4_step(lambda xx, uu: cartesian_rhs(xx, uu, p, math), state, (a, dd), h, 1)
        state[3] = max(state[3], 0.0)
        state[4] = min(max(state[4], -p.steer_max), p.steer_max)
    return np.array(state)


@pytest.mark.parametrize("substeps", [1, 4])
def test_plant_step_is_the_generic_rk4_of_the_model(substeps):
    plant = Plant(AV21, dt=0.1, substeps=substeps)
    rng = np.random.default_rng(0)
    for i in range(2000):
        x = np.array([rng.uniform(-500, 500), rng.uniform(-500, 500), rng.uniform(-7, 7),
                      rng.uniform(0, 90) if i % 5 else rng.uniform(0, 0.3), rng.uniform(-0.26, 0.26)])
        u = np.array([rng.uniform(-12, 4), rng.uniform(-0.5, 0.5)])
        np.testing.assert_array_equal(plant.step(x, u), reference_plant_step(plant, x, u))


def test_corner_list_matches_the_array_footprint():
    rng = np.random.default_rng(1)
    for _ in range(500):
        x, y, psi = rng.uniform(-1e3, 1e3), rng.uniform(-1e3, 1e3), rng.uniform(-7, 7)
        np.testing.assert_array_equal(np.array(footprint_corner_list(x, y, psi, AV21)),
                                      footprint_corners(x, y, psi, AV21))
    corners = footprint_corners(0.0, 0.0, 0.7, AV21)
    assert np.hypot(corners[:, 0], corners[:, 1]).max() <= footprint_radius(AV21) + 1e-12


@pytest.mark.parametrize("t", [np.arange(21) * 0.075,                                    # evenly spaced
                               np.concatenate([np.arange(10) * 0.075, 0.675 + np.arange(1, 12) * 0.15]),
                               np.array([0.0, 0.1]), np.array([0.0, 0.1, 0.35])])
def test_grid_gradient_is_numpy_gradient(t):
    from sofar_env._gradient import GridGradient

    grad = GridGradient(t)
    f = np.random.default_rng(5).normal(size=(4, t.size)) * 50.0
    np.testing.assert_array_equal(grad(f), np.gradient(f, t, axis=-1))
    np.testing.assert_array_equal(grad(f[0]), np.gradient(f[0], t))
    assert grad(np.zeros((0, t.size))).shape == (0, t.size)
    with pytest.raises(ValueError, match="samples"):
        grad(np.zeros(t.size + 1))
