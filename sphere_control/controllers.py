"""Building a controller from its kind and the kick model it starts from (one place)."""

import math

import numpy as np

from sphere_control.basic import BasicController, BasicParams
from sphere_control.extended import ExtendedController, ExtendedParams
from sphere_sim.discrete import angle_between

CONTROLLER_KINDS = ('basic', 'extended')
DEFAULT_PHI_MIN_RAD = math.radians(0.05)  # Fig. 13's tighter resting band


def full_kick_width_rad(kick_plant):
    """Rotation of a full kick from rest: the model's prior for every action's width."""
    up = np.array([0.0, 0.0, 1.0])
    return angle_between(up, kick_plant.kick(up, 0, 1.0).normal)


def make_controller(kind, kick_plant, phi_min_rad=DEFAULT_PHI_MIN_RAD):
    """A fresh controller of ``kind`` whose model is ``kick_plant`` (directions and width).

    Raises
    ------
    ValueError
        For an unknown kind.
    """
    directions = tuple(kick_plant.directions_rad)
    width = full_kick_width_rad(kick_plant)
    if kind == 'basic':
        return BasicController(BasicParams(phi_min_rad, directions, width))
    if kind == 'extended':
        return ExtendedController(ExtendedParams(phi_min_rad, width, directions))
    raise ValueError(f'unknown controller {kind!r}; choose one of {", ".join(CONTROLLER_KINDS)}')
