"""Angular errors between the surface normal and its reference, eqs. (54)-(58), and Fig. 11.

All directions are polar angles (rad) in the x-y plane, measured from the x axis towards y,
the convention of :data:`sphere_sim.kicks.discrete.DIAGONAL_DIRECTIONS_RAD`.
"""

import math
from collections.abc import Iterable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from sphere_sim.kicks.discrete import normal_from_xy
from sphere_sim.model.rotations import angle_between

FULL_TURN_RAD = 2.0 * math.pi


def wrap_angle_rad(angle_rad: float) -> float:
    """The angle mapped into [-pi, pi] (rad)."""
    return math.remainder(float(angle_rad), FULL_TURN_RAD)


def error_vector(normal: ArrayLike, reference: ArrayLike) -> NDArray[np.float64]:
    """Cartesian error e = xi_r - xi_n of eq. (54).

    Parameters
    ----------
    normal, reference : ndarray, shape (3,)
        Unit surface normal and its reference.

    Returns
    -------
    ndarray, shape (3,)
    """
    return np.asarray(reference, dtype=float) - np.asarray(normal, dtype=float)


def error_angle_rad(normal: ArrayLike, reference: ArrayLike) -> float:
    """Absolute error angle Phi in [0, pi] of eq. (55) (rad), robust for tiny angles."""
    return angle_between(normal, reference)


def error_direction_rad(normal: ArrayLike, reference: ArrayLike) -> float:
    """Polar angle Theta in [0, 2 pi) of the error's x-y part, eqs. (56)-(57) (rad).

    ``atan2`` folded into [0, 2 pi) equals the paper's case distinction on e_y. A zero x-y
    error has no direction; 0 is returned for it.
    """
    e = error_vector(normal, reference)
    if e[0] == 0.0 and e[1] == 0.0:
        return 0.0
    return math.atan2(e[1], e[0]) % FULL_TURN_RAD


def nearest_action(theta_rad: float, directions_rad: Iterable[float]) -> int:
    """Eq. (58): index of the kick direction closest to Theta (differences wrapped)."""
    gaps = [abs(wrap_angle_rad(sigma - theta_rad)) for sigma in directions_rad]
    return int(np.argmin(gaps))


def displacement_xy(normal_before: ArrayLike, normal_after: ArrayLike) -> NDArray[np.float64]:
    """x-y displacement of the normal, shape (2,)."""
    return np.asarray(normal_after, dtype=float)[:2] - np.asarray(normal_before, dtype=float)[:2]


def closest_point_on_kick_line(normal: ArrayLike, direction_rad: float, reference: ArrayLike,
                               ) -> tuple[NDArray[np.float64], float]:
    """Fig. 11: the point of the kick line closest to the reference.

    The kick line runs through the normal's x-y point along ``direction_rad``.

    Parameters
    ----------
    normal, reference : ndarray, shape (3,)
    direction_rad : float

    Returns
    -------
    target : ndarray, shape (3,)
        The unit normal xi_n* whose x-y point is the foot of the perpendicular.
    travel : float
        Signed distance along the line to it (x-y units; negative: behind the normal).
    """
    unit = np.array([math.cos(direction_rad), math.sin(direction_rad)])
    travel = float(unit @ displacement_xy(normal, reference))
    xy = np.asarray(normal, dtype=float)[:2] + travel * unit
    radius = math.hypot(*xy)
    if radius >= 1.0:  # beyond the horizon: keep the x-y direction, stay a unit vector
        xy = xy / radius * math.sin(0.5 * math.pi - 1e-9)
    return normal_from_xy(*xy), travel


def target_rotation_rad(normal: ArrayLike, direction_rad: float, reference: ArrayLike) -> float:
    """Psi*: signed rotation (rad) from the normal to the closest point of its kick line."""
    target, travel = closest_point_on_kick_line(normal, direction_rad, reference)
    return math.copysign(angle_between(normal, target), travel)
