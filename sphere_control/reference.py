"""References for the surface normal: setpoints and the trajectory of eq. (64).

A reference gives the wanted x-y point of the normal at a time. Points outside the reachable
cone (the paper's state space, 40 deg about z) are clamped to its edge along their own
direction, and the sample says so, so a closed loop can refuse them or report that it steered
to the nearest reachable normal instead.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from sphere_sim.kicks.discrete import CONE_HALF_ANGLE_RAD, normal_from_xy


class Reference(Protocol):
    """What a closed loop follows: the wanted x-y point of the normal and its velocity at a
    time, and whether it stays where it is (a setpoint)."""

    @property
    def is_constant(self) -> bool: ...

    def xy_at(self, time_s: float) -> NDArray[np.float64]: ...

    def velocity_xy(self, time_s: float) -> NDArray[np.float64]: ...


@dataclasses.dataclass(frozen=True)
class ReferenceSample:
    """A reference at one time.

    Attributes
    ----------
    normal : ndarray, shape (3,)
        The unit normal to steer to (clamped into the cone).
    requested_xy : ndarray, shape (2,)
        What the reference asked for.
    clamped : bool
        True if the request lay outside the cone (or was not a unit vector's x-y part).
    """

    normal: NDArray[np.float64]
    requested_xy: NDArray[np.float64]
    clamped: bool


def clamp_to_cone(xy: ArrayLike, cone_half_angle_rad: float = CONE_HALF_ANGLE_RAD,
                  ) -> tuple[NDArray[np.float64], bool]:
    """The x-y point moved onto the cone's edge if it lies beyond; (xy (2,), clamped)."""
    xy = np.asarray(xy, dtype=float)
    limit = math.sin(cone_half_angle_rad)
    radius = math.hypot(*xy)
    if radius <= limit:
        return xy.copy(), False
    return xy * (limit / radius), True


@dataclasses.dataclass(frozen=True)
class Setpoint:
    """A constant reference, given by the x-y part of the wanted normal."""

    xy: tuple[float, float]
    is_constant = True

    @classmethod
    def from_normal(cls, normal: ArrayLike) -> Setpoint:
        n = np.asarray(normal, dtype=float)
        n = n / np.linalg.norm(n)
        return cls((float(n[0]), float(n[1])))

    def xy_at(self, time_s: float) -> NDArray[np.float64]:
        return np.array(self.xy, dtype=float)

    def velocity_xy(self, time_s: float) -> NDArray[np.float64]:
        return np.zeros(2)


@dataclasses.dataclass(frozen=True)
class CircleTrajectory:
    """Eq. (64): [x, y] = A_max cos(2 pi f1 t) [cos(2 pi f1 t), sin(2 pi f1 t)].

    A circle of diameter A_max through the origin, run twice per period 1/f1.

    Attributes
    ----------
    amplitude : float
        A_max (x-y units of the normal; 0.44 is 26 deg of tilt).
    frequency_hz : float
        f1 (Hz).
    """

    amplitude: float = 0.44
    frequency_hz: float = 0.02
    is_constant = False

    def xy_at(self, time_s: float) -> NDArray[np.float64]:
        phase = 2.0 * math.pi * self.frequency_hz * time_s
        return self.amplitude * math.cos(phase) * np.array([math.cos(phase), math.sin(phase)])

    def velocity_xy(self, time_s: float) -> NDArray[np.float64]:
        """d/dt of :meth:`xy_at` (1/s): the point is (A/2)(1 + cos 2phi, sin 2phi)."""
        rate = 2.0 * math.pi * self.frequency_hz
        double = 2.0 * rate * time_s
        return self.amplitude * rate * np.array([-math.sin(double), math.cos(double)])


@dataclasses.dataclass(frozen=True)
class ScheduledReference:
    """A setpoint until ``switch_s``, then a trajectory entered ``offset_s`` into it: the
    reference node's schedule (the demo's scenario), for the offline loop too.

    ``switch_s`` < 0: the setpoint for ever.
    """

    setpoint: Setpoint
    trajectory: CircleTrajectory
    switch_s: float = -1.0
    offset_s: float = 0.0

    @property
    def is_constant(self) -> bool:
        return self.switch_s < 0.0

    def phase_at(self, time_s: float) -> str:
        """'setpoint' or 'trajectory'."""
        return 'trajectory' if 0.0 <= self.switch_s <= time_s else 'setpoint'

    def xy_at(self, time_s: float) -> NDArray[np.float64]:
        if self.phase_at(time_s) == 'trajectory':
            return self.trajectory.xy_at(time_s - self.switch_s + self.offset_s)
        return self.setpoint.xy_at(time_s)

    def velocity_xy(self, time_s: float) -> NDArray[np.float64]:
        if self.phase_at(time_s) == 'trajectory':
            return self.trajectory.velocity_xy(time_s - self.switch_s + self.offset_s)
        return self.setpoint.velocity_xy(time_s)


def sample(reference: Reference, time_s: float,
           cone_half_angle_rad: float = CONE_HALF_ANGLE_RAD) -> ReferenceSample:
    """The :class:`ReferenceSample` of ``reference`` at ``time_s``."""
    return _sample_xy(reference.xy_at(time_s), cone_half_angle_rad)


def preview(reference: Reference, time_s: float, horizon_s: float,
            cone_half_angle_rad: float = CONE_HALF_ANGLE_RAD) -> ReferenceSample:
    """Where ``reference`` will be ``horizon_s`` after ``time_s`` if it goes on as it moves at
    ``time_s``: its tangent, as the controller node's estimate from the recent samples is
    (:mod:`sphere_control.reference_motion`). A jump ahead (a scheduled switch) is not
    foreseen; along eq. (64) the tangent leaves the circle by at most 1.1e-5 in x-y (6e-4 deg)
    over 40 ms."""
    return _sample_xy(reference.xy_at(time_s) + reference.velocity_xy(time_s) * horizon_s,
                      cone_half_angle_rad)


def _sample_xy(requested: NDArray[np.float64], cone_half_angle_rad: float) -> ReferenceSample:
    xy, clamped = clamp_to_cone(requested, cone_half_angle_rad)
    return ReferenceSample(normal_from_xy(*xy), requested, clamped)
