"""Footprint geometry and the separating-axis collision test."""

import numpy as np
import pytest

from sofar_env.geometry import footprint_corners, rectangles_intersect
from sofar_env.vehicle import AV21


def test_footprint_has_the_car_dimensions():
    c = footprint_corners(10.0, -3.0, 0.0, AV21)
    assert c.shape == (4, 2)
    assert c[:, 0].max() - c[:, 0].min() == pytest.approx(AV21.length)
    assert c[:, 1].max() - c[:, 1].min() == pytest.approx(AV21.width)
    rotated = footprint_corners(0.0, 0.0, np.pi / 2, AV21)
    assert rotated[:, 1].max() == pytest.approx(AV21.cg_to_front)


@pytest.mark.parametrize(
    "dx, dy, dpsi, expected",
    [
        (4.8, 0.0, 0.0, True),  # nose to tail, 10 cm overlap
        (5.0, 0.0, 0.0, False),  # 10 cm gap
        (0.0, 1.85, 0.0, True),  # side by side, 5 cm overlap
        (0.0, 1.95, 0.0, False),  # side by side, 5 cm gap
        (3.0, 2.2, 0.6, True),  # rotated: the corner reaches in
        (3.0, 3.5, 0.6, False),
        (0.0, 0.0, 1.0, True),
    ],
)
def test_rectangle_intersection_true_and_false(dx, dy, dpsi, expected):
    a = footprint_corners(0.0, 0.0, 0.0, AV21)
    b = footprint_corners(dx, dy, dpsi, AV21)
    assert bool(rectangles_intersect(a, b)) is expected
    assert bool(rectangles_intersect(b, a)) is expected


def test_rotated_corner_case_is_geometrically_right():
    # b rotated by 45 deg with a corner pointing at a's side: a diamond whose tip is 2 cm inside / outside
    a = footprint_corners(0.0, 0.0, 0.0, AV21)
    half_diag = np.hypot(AV21.length / 2, AV21.width / 2)
    ang = np.arctan2(AV21.width / 2, AV21.length / 2)
    psi = -np.pi / 2 + ang  # a front corner of b points straight down (-y)
    for gap, expected in [(-0.02, True), (0.02, False)]:
        y = AV21.width / 2 + half_diag + gap
        b = footprint_corners(0.0, y, psi, AV21)
        assert b[:, 1].min() == pytest.approx(AV21.width / 2 + gap)
        assert bool(rectangles_intersect(a, b)) is expected


def test_vectorised_over_many_obstacles():
    a = footprint_corners(0.0, 0.0, 0.0, AV21)
    others = footprint_corners(np.array([4.8, 5.0, 0.0]), np.array([0.0, 0.0, 1.95]), np.zeros(3), AV21)
    np.testing.assert_array_equal(rectangles_intersect(a[None], others), [True, False, False])
