"""KickPlants for controller studies beside the lookup table.

* :class:`AnalyticKickPlant`: each kick moves the normal's x-y point by a width h(u_K) along the
  action's direction; fast and exact, for tests and for the paper's kick size.
* :class:`EightDirectionPlant`: adds axis-parallel kicks to a four-direction plant by turning
  its diagonal kick by 45 deg (an assumption: the device has no such symmetry and the table
  holds only the diagonal kick; see docs/control.md).

The physics' own kick models, the continuous model kicked from rest
(:class:`sphere_sim.kicks.continuous_kicks.ContinuousKickPlant`) and the twin's plant kicked on
(:class:`sphere_sim.twin.plants.TwinKickPlant`), live with the physics.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

from sphere_control.geometry import wrap_angle_rad
from sphere_sim.kicks.discrete import (
    CONE_HALF_ANGLE_RAD,
    DIAGONAL_DIRECTIONS_RAD,
    EIGHT_DIRECTIONS_RAD,
    KickPlant,
    KickResult,
    normal_from_xy,
)

if TYPE_CHECKING:
    pass

EIGHTH_TURN_RAD = 0.25 * math.pi


def _turn_xy(normal: ArrayLike, angle_rad: float) -> NDArray[np.float64]:
    """The normal turned about z by ``angle_rad``, shape (3,)."""
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    n = np.asarray(normal, dtype=float)
    return np.array([c * n[0] - s * n[1], s * n[0] + c * n[1], n[2]])


class AnalyticKickPlant:
    """Kicks of width h(u) = full_width * u**exponent * (1 - softening * tilt / cone).

    Parameters
    ----------
    full_width_rad : float
        x-y displacement of a full kick from the level state (rad, small-angle).
    directions_rad : tuple of float
        True direction of each action (rad).
    exponent : float
        Shape of the intensity characteristic (1: linear; >1: convex like Fig. 10).
    softening : float
        Relative loss of width at the cone's edge (Fig. 10: widths shrink with tilt).
    """

    def __init__(self, full_width_rad: float,
                 directions_rad: Iterable[float] = DIAGONAL_DIRECTIONS_RAD,
                 exponent: float = 1.0, softening: float = 0.0) -> None:
        self.full_width_rad = float(full_width_rad)
        self.directions_rad = tuple(directions_rad)
        self.exponent = float(exponent)
        self.softening = float(softening)

    def width_rad(self, normal: NDArray[np.float64], intensity: float) -> float:
        tilt = math.asin(min(1.0, math.hypot(normal[0], normal[1])))
        scale = 1.0 - self.softening * tilt / CONE_HALF_ANGLE_RAD
        return self.full_width_rad * float(np.clip(intensity, 0.0, 1.0)) ** self.exponent * scale

    def kick(self, normal: NDArray[np.float64], action: int, intensity: float) -> KickResult:
        sigma = self.directions_rad[action]
        h = self.width_rad(normal, intensity)
        xy = np.asarray(normal, dtype=float)[:2] + h * np.array([math.cos(sigma), math.sin(sigma)])
        return KickResult(normal_from_xy(*xy))


class EightDirectionPlant:
    """Diagonal kicks from ``base``; axis-parallel ones are its kicks turned by 45 deg.

    For an axis-parallel action at angle phi the state is turned by -45 deg, kicked with the
    base action at phi - 45 deg, and the outcome turned back.
    """

    def __init__(self, base: KickPlant) -> None:
        self.base = base
        self.directions_rad = EIGHT_DIRECTIONS_RAD

    def _base_action(self, direction_rad: float) -> tuple[int, float]:
        gaps = [abs(wrap_angle_rad(d - direction_rad)) for d in self.base.directions_rad]
        return int(np.argmin(gaps)), min(gaps)

    def kick(self, normal: NDArray[np.float64], action: int, intensity: float) -> KickResult:
        phi = self.directions_rad[action]
        base_action, gap = self._base_action(phi)
        if gap < 1e-9:
            return self.base.kick(normal, base_action, intensity)
        base_action, _ = self._base_action(phi - EIGHTH_TURN_RAD)
        turned = self.base.kick(_turn_xy(normal, -EIGHTH_TURN_RAD), base_action, intensity)
        return KickResult(_turn_xy(turned.normal, EIGHTH_TURN_RAD), turned.peak_deviation_rad,
                          turned.settle_time_s)
