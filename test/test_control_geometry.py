"""Error angles, action selection and the kick line of eqs. (54)-(58) and Fig. 11."""

import math

import numpy as np
import pytest

from sphere_control.geometry import (
    closest_point_on_kick_line,
    error_angle_rad,
    error_direction_rad,
    error_vector,
    nearest_action,
    target_rotation_rad,
    wrap_angle_rad,
)
from sphere_sim.kicks.discrete import DIAGONAL_DIRECTIONS_RAD, normal_from_xy

LEVEL = np.array([0.0, 0.0, 1.0])


@pytest.mark.parametrize(('xy', 'theta_deg'), [((0.01, 0.0), 0.0), ((0.0, 0.01), 90.0),
                                               ((-0.01, 0.0), 180.0), ((0.0, -0.01), 270.0),
                                               ((0.01, -0.01), 315.0), ((-0.01, 0.01), 135.0)])
def test_theta_is_the_polar_angle_of_the_error_in_zero_to_two_pi(xy, theta_deg):
    theta = error_direction_rad(LEVEL, normal_from_xy(*xy))
    assert 0.0 <= theta < 2.0 * math.pi
    assert math.degrees(theta) == pytest.approx(theta_deg, abs=1e-9)


def test_theta_follows_eq_57_case_distinction():
    rng = np.random.default_rng(3)
    for _ in range(50):
        n = normal_from_xy(*rng.uniform(-0.3, 0.3, 2))
        r = normal_from_xy(*rng.uniform(-0.3, 0.3, 2))
        e = error_vector(n, r)
        tilde = math.acos(e[0] / math.hypot(e[0], e[1]))
        expected = tilde if e[1] >= 0.0 else 2.0 * math.pi - tilde
        assert error_direction_rad(n, r) == pytest.approx(expected, abs=1e-12)


def test_phi_is_the_angle_between_normals_even_when_tiny():
    r = normal_from_xy(0.01, 0.02)
    assert error_angle_rad(LEVEL, r) == pytest.approx(math.asin(math.hypot(0.01, 0.02)))
    tiny = normal_from_xy(1e-9, 0.0)
    assert error_angle_rad(LEVEL, tiny) == pytest.approx(1e-9, rel=1e-6)


def test_nearest_action_wraps_around_the_circle():
    directions = DIAGONAL_DIRECTIONS_RAD  # -45, 45, 135, -135 deg
    assert nearest_action(math.radians(350.0), directions) == 0
    assert nearest_action(math.radians(10.0), directions) == 1
    assert nearest_action(math.radians(181.0), directions) == 3
    assert nearest_action(math.radians(179.0), directions) == 2
    assert abs(wrap_angle_rad(3.0 * math.pi)) == pytest.approx(math.pi)
    assert wrap_angle_rad(math.radians(350.0)) == pytest.approx(math.radians(-10.0))


def test_closest_point_is_the_foot_of_the_perpendicular():
    normal = normal_from_xy(0.1, 0.0)
    reference = normal_from_xy(0.1, 0.02)
    target, travel = closest_point_on_kick_line(normal, math.radians(45.0), reference)
    assert travel == pytest.approx(0.02 / math.sqrt(2.0))
    np.testing.assert_allclose(target[:2], [0.11, 0.01], atol=1e-12)
    assert np.linalg.norm(target) == pytest.approx(1.0)
    # the rest of the error is perpendicular to the kick line
    rest = reference[:2] - target[:2]
    assert rest @ np.array([1.0, 1.0]) == pytest.approx(0.0, abs=1e-15)


def test_target_rotation_is_negative_behind_the_normal():
    normal = normal_from_xy(0.0, 0.0)
    ahead = target_rotation_rad(normal, 0.0, normal_from_xy(0.01, 0.005))
    behind = target_rotation_rad(normal, 0.0, normal_from_xy(-0.01, 0.005))
    assert ahead == pytest.approx(math.asin(0.01), rel=1e-6)
    assert behind == pytest.approx(-math.asin(0.01), rel=1e-6)
