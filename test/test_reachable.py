"""The reachable speed along a reference: the ray's exit from the hull of the kicks."""

import math

import numpy as np
import pytest

from sphere_control.reachable import kick_vectors, reach_per_kick, speed_ratios
from sphere_sim.kicks.discrete import DIAGONAL_DIRECTIONS_RAD

W = math.radians(0.54)


def test_along_a_kick_the_plant_moves_a_full_kick_per_period():
    kicks = kick_vectors(DIAGONAL_DIRECTIONS_RAD, W)
    for d in DIAGONAL_DIRECTIONS_RAD:
        assert reach_per_kick(kicks, d) == pytest.approx(W, rel=1e-12)


def test_between_two_kicks_at_right_angles_it_moves_their_mean():
    kicks = kick_vectors(DIAGONAL_DIRECTIONS_RAD, W)
    # Halfway between the -45 and +45 deg kicks: alternate them, W cos 45 deg per kick.
    assert reach_per_kick(kicks, 0.0) == pytest.approx(W / math.sqrt(2.0), rel=1e-12)
    # At 22.5 deg from the +45 kick, on the edge from the +45 to the -45 kick:
    theta = math.radians(22.5)
    expected = W * math.cos(math.radians(45.0)) / math.cos(theta)
    assert reach_per_kick(kicks, theta) == pytest.approx(expected, rel=1e-12)


def test_eight_directions_reach_further_between_the_diagonals():
    four = kick_vectors(DIAGONAL_DIRECTIONS_RAD, W)
    eight = kick_vectors(np.radians(np.arange(-45.0, 315.0, 45.0)), W)
    assert reach_per_kick(eight, 0.0) == pytest.approx(W)
    assert reach_per_kick(eight, 0.0) > reach_per_kick(four, 0.0)


def test_turned_kicks_move_the_hull_and_a_lost_side_reaches_nothing():
    kicks = kick_vectors(DIAGONAL_DIRECTIONS_RAD, W)
    # Only the +45 and +135 deg kicks: nothing has a component towards -90 deg.
    assert reach_per_kick(kicks[[1, 2]], math.radians(-90.0)) == 0.0
    # Turned by 33 deg the kicks lie at -12 and 78 deg about 0 deg: the ray leaves their chord
    # (at W cos 45 deg from 0, normal at 33 deg) at W cos 45 / cos 33.
    turned = kick_vectors(np.array(DIAGONAL_DIRECTIONS_RAD) + math.radians(33.0), W)
    expected = W * math.cos(math.radians(45.0)) / math.cos(math.radians(33.0))
    assert reach_per_kick(turned, 0.0) == pytest.approx(expected, rel=1e-12)


def test_speed_ratios_flag_a_reference_faster_than_the_hull():
    kicks = kick_vectors(DIAGONAL_DIRECTIONS_RAD, W)
    steps = np.array([[0.5 * W, 0.0], [0.0, 0.0], [W, 0.0]])
    ratios = speed_ratios(steps, lambda i: kicks)
    assert ratios == pytest.approx([0.5 * math.sqrt(2.0), 0.0, math.sqrt(2.0)])
