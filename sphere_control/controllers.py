"""The one factory of controllers: a kind, a resting band and a kick model in, a controller out.

The evaluation, the closed-loop studies and the controller node all build their controllers
here; the kinds are one list, :class:`ControllerKind`.
"""

import enum
import math
from collections.abc import Iterable
from typing import Protocol, runtime_checkable

import numpy as np

from sphere_control.basic import BasicController, BasicParams
from sphere_control.command import Controller
from sphere_control.extended import ExtendedController, ExtendedParams
from sphere_control.intensity_calibration import CalibratedKicks
from sphere_sim.kicks.discrete import KickPlant
from sphere_sim.model.rotations import angle_between

DEFAULT_PHI_MIN_RAD = math.radians(0.05)  # Fig. 13's tighter resting band


class ControllerKind(enum.Enum):
    """The controllers of §5. ``PRELEARNED`` is the extended one after it has first learned on
    the device it will run on (Fig. 13); it needs that device, so only the studies offer it."""

    BASIC = 'basic'
    EXTENDED = 'extended'
    PRELEARNED = 'pre-learned extended'


# What a running twin can choose (the controller node's ``controller`` parameter).
CONTROLLER_KINDS = (ControllerKind.BASIC.value, ControllerKind.EXTENDED.value)


def full_kick_width_rad(kick_plant: KickPlant) -> float:
    """Rotation of a full kick from rest: the model's prior for every action's width."""
    up = np.array([0.0, 0.0, 1.0])
    return angle_between(up, kick_plant.kick(up, 0, 1.0).normal)


@runtime_checkable
class StrayKicksKnown(Protocol):
    """A kick model that knows how far its programmes can slip the sphere off their actions
    (the lookup tables)."""

    def largest_stray_kick_rad(self) -> float: ...


def direction_learning_floor_rad(kick_plant: KickPlant) -> float:
    """The shortest kick that teaches sigma_a (rad), calibrated on the kick model.

    The paper learns sigma_a from every kick (eq. 61, at alpha_sigma = 0.9). On a model whose
    programmes can slip the sphere in a direction of their own (below the pull-in, or from far
    out: the ratchet of docs/parameters.md), a kick no longer than the longest such slip tells
    nothing of its action's direction, and eq. (61) would adopt that slip's. So the floor is the
    longest kick of the model with no component along its action (more than 90 deg off), 0 on
    a model that has none (learning from every kick, as the paper). A model wrapped in an
    intensity calibration is read through it.
    """
    inner = kick_plant.kicks if isinstance(kick_plant, CalibratedKicks) else kick_plant
    return inner.largest_stray_kick_rad() if isinstance(inner, StrayKicksKnown) else 0.0


def make_controller(kind: ControllerKind | str, phi_min_rad: float, full_width_rad: float,
                    directions_rad: Iterable[float],
                    direction_learning_min_rad: float = 0.0,
                    ) -> Controller:
    """A fresh controller of ``kind`` (a :class:`ControllerKind` or its value).

    ``PRELEARNED`` gives an extended controller still to be taught by its caller.
    ``direction_learning_min_rad`` is the extended controller's (:class:`ExtendedParams`).

    Raises
    ------
    ValueError
        For an unknown kind.
    """
    try:
        kind = ControllerKind(kind)
    except ValueError:
        raise ValueError(f'unknown controller {kind!r}; choose one of '
                         f'{", ".join(k.value for k in ControllerKind)}') from None
    directions = tuple(directions_rad)
    if kind is ControllerKind.BASIC:
        return BasicController(BasicParams(phi_min_rad, full_width_rad, directions))
    return ExtendedController(ExtendedParams(
        phi_min_rad, full_width_rad, directions,
        direction_learning_min_rad=direction_learning_min_rad))


def controller_for(kind: ControllerKind | str, kick_plant: KickPlant,
                   phi_min_rad: float = DEFAULT_PHI_MIN_RAD,
                   ) -> Controller:
    """A controller whose model is ``kick_plant``'s directions, full-kick width and
    direction-learning floor (:func:`direction_learning_floor_rad`)."""
    return make_controller(kind, phi_min_rad, full_kick_width_rad(kick_plant),
                           kick_plant.directions_rad, direction_learning_floor_rad(kick_plant))
