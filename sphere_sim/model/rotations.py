"""Orientation helpers: unit quaternions inside, Cardan angles at the interface.

The paper's Cardan angles psi = [alpha, beta, gamma] give the body-to-inertial rotation
I_A_S = Rx(alpha) Ry(beta) Rz(gamma) (eq. A1). Integration uses a unit quaternion
[w, x, y, z] so that nothing breaks at beta = +-90 deg (gimbal lock).
"""

import math

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

# quat_rows and quat_to_matrix are numba kernels: numba reads their types from the arguments,
# hence the `type: ignore[no-untyped-def]` on their defs.

# Closer than this to beta = +-90 deg, alpha and gamma turn about one axis (gimbal lock).
GIMBAL_LOCK_MARGIN_RAD = 1e-9


@numba.njit(cache=True, inline='always')
def quat_rows(q):  # type: ignore[no-untyped-def]
    """Rows of the body-to-inertial rotation matrix of a quaternion (normalised here).

    A tuple of three row tuples, so that the compiled kernels allocate nothing.
    """
    n = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    w, x, y, z = q[0] / n, q[1] / n, q[2] / n, q[3] / n
    return ((1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - w * z), 2.0 * (x * z + w * y)),
            (2.0 * (x * y + w * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - w * x)),
            (2.0 * (x * z - w * y), 2.0 * (y * z + w * x), 1.0 - 2.0 * (x * x + y * y)))


@numba.njit(cache=True)
def quat_to_matrix(q):  # type: ignore[no-untyped-def]
    """Body-to-inertial rotation matrix of a quaternion (normalised here), shape (3, 3)."""
    rows = quat_rows(q)
    R = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            R[i, j] = rows[i][j]
    return R


def cardan_to_matrix(alpha: float, beta: float, gamma: float) -> NDArray[np.float64]:
    """I_A_S of eq. (A1)."""
    ca, sa = math.cos(alpha), math.sin(alpha)
    cb, sb = math.cos(beta), math.sin(beta)
    cg, sg = math.cos(gamma), math.sin(gamma)
    return np.array([
        [cb * cg, -cb * sg, sb],
        [ca * sg + cg * sa * sb, ca * cg - sa * sb * sg, -cb * sa],
        [sa * sg - ca * cg * sb, cg * sa + ca * sb * sg, ca * cb],
    ])


def matrix_to_quat(R: ArrayLike) -> NDArray[np.float64]:
    """Unit quaternion [w, x, y, z] with w >= 0 of a rotation matrix (Shepperd's method)."""
    R = np.asarray(R, dtype=float)
    trace = R[0, 0] + R[1, 1] + R[2, 2]
    if trace > 0.0:
        s = 2.0 * math.sqrt(1.0 + trace)
        q = np.array([0.25 * s, (R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s,
                      (R[1, 0] - R[0, 1]) / s])
    elif R[0, 0] > R[1, 1] and R[0, 0] > R[2, 2]:
        s = 2.0 * math.sqrt(1.0 + R[0, 0] - R[1, 1] - R[2, 2])
        q = np.array([(R[2, 1] - R[1, 2]) / s, 0.25 * s, (R[0, 1] + R[1, 0]) / s,
                      (R[0, 2] + R[2, 0]) / s])
    elif R[1, 1] > R[2, 2]:
        s = 2.0 * math.sqrt(1.0 + R[1, 1] - R[0, 0] - R[2, 2])
        q = np.array([(R[0, 2] - R[2, 0]) / s, (R[0, 1] + R[1, 0]) / s, 0.25 * s,
                      (R[1, 2] + R[2, 1]) / s])
    else:
        s = 2.0 * math.sqrt(1.0 + R[2, 2] - R[0, 0] - R[1, 1])
        q = np.array([(R[1, 0] - R[0, 1]) / s, (R[0, 2] + R[2, 0]) / s,
                      (R[1, 2] + R[2, 1]) / s, 0.25 * s])
    q /= np.linalg.norm(q)
    return -q if q[0] < 0.0 else q


def cardan_to_quat(alpha: float, beta: float, gamma: float) -> NDArray[np.float64]:
    return matrix_to_quat(cardan_to_matrix(alpha, beta, gamma))


def matrix_to_cardan(R: NDArray[np.float64]) -> NDArray[np.float64]:
    """Cardan angles [alpha, beta, gamma] (rad) of I_A_S; gamma = 0 at gimbal lock."""
    sb = min(1.0, max(-1.0, R[0, 2]))
    beta = math.asin(sb)
    if math.cos(beta) < GIMBAL_LOCK_MARGIN_RAD:
        # alpha and gamma rotate about the same axis: report the whole angle as alpha.
        return np.array([math.atan2(R[2, 1], R[1, 1]), beta, 0.0])
    return np.array([math.atan2(-R[1, 2], R[2, 2]), beta, math.atan2(-R[0, 1], R[0, 0])])


def quat_to_cardan(q: ArrayLike) -> NDArray[np.float64]:
    return matrix_to_cardan(quat_to_matrix(np.asarray(q, dtype=float)))


def surface_normal_of_quat(q: ArrayLike) -> NDArray[np.float64]:
    """Unit normal of the flat face in the inertial frame: the body z axis, eq. (53)."""
    return quat_to_matrix(np.asarray(q, dtype=float))[:, 2].copy()


def angle_between(a: ArrayLike, b: ArrayLike) -> float:
    """Angle (rad) between two unit vectors, robust for tiny angles."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    return math.atan2(np.linalg.norm(np.cross(a, b)), float(a @ b))
