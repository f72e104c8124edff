"""The twin drawn for RViz or Foxglove: sphere, mirror face and beams as a MarkerArray.

Geometry is to scale (m) in ``world``. The mirror is a thin disc on the flat face; beams are
boxes from their suspension towards the centre, tilted by phi.
"""

import math
from typing import Any

import numpy as np
from geometry_msgs.msg import Point, Pose, Quaternion, Vector3
from numpy.typing import ArrayLike, NDArray
from std_msgs.msg import ColorRGBA
from visualization_msgs.msg import Marker, MarkerArray

from msg_defs.topics import MARKERS

SPHERE_RADIUS_M = 1.0e-3
FACE_RADIUS_M = 1.0e-3  # the cut at phi = 90 deg leaves a face of the sphere's radius
FACE_THICKNESS_M = 20e-6
BEAM_LENGTH_M = 1.4e-3
BEAM_WIDTH_M = 200e-6
BEAM_THICKNESS_M = 50e-6
BEAM_SUSPENSION_RADIUS_M = 1.4e-3 + 0.4e-3  # tip at d_B / 2 from the centre
NAMESPACE = 'sphere_twin'
# The normal's arrow: out of the mirror face, long enough to read a tenth of a degree.
NORMAL_ARROW_LENGTH_M = 3e-3
NORMAL_ARROW_SHAFT_M = 50e-6
REFERENCE_NAMESPACE = 'sphere_twin/reference'
REFERENCE_RGBA = (0.2, 0.9, 0.3, 0.8)
# Where the reference's arrow starts: the centre of a sphere resting level on undeflected tips
# (tips at d_B / 2 = 0.4 mm from the axis); the reference node knows no state.
NOMINAL_CENTRE_M = np.array([0.0, 0.0, math.sqrt(SPHERE_RADIUS_M**2 - 0.4e-3**2)])


def _quaternion_from_normal(normal: NDArray[np.float64]) -> NDArray[np.float64]:
    """Shortest rotation taking +z to ``normal`` (w, x, y, z)."""
    z = np.array([0.0, 0.0, 1.0])
    axis = np.cross(z, normal)
    s = float(np.linalg.norm(axis))
    c = float(np.dot(z, normal))
    if s < 1e-15:
        return np.array([1.0, 0.0, 0.0, 0.0]) if c > 0 else np.array([0.0, 1.0, 0.0, 0.0])
    half = 0.5 * math.atan2(s, c)
    return np.concatenate([[math.cos(half)], math.sin(half) * axis / s])


def _marker(marker_id: int, kind: int, stamp: Any, position: NDArray[np.float64],
            quaternion_wxyz: NDArray[np.float64], scale: list[float],
            rgba: tuple[float, float, float, float]) -> Any:
    m = Marker()
    m.header.frame_id = MARKERS.frame_id
    m.header.stamp = stamp
    m.ns = NAMESPACE
    m.id = marker_id
    m.type = kind
    m.action = Marker.ADD
    w, x, y, z = (float(v) for v in quaternion_wxyz)
    m.pose = Pose(position=Point(x=float(position[0]), y=float(position[1]),
                                 z=float(position[2])),
                  orientation=Quaternion(w=w, x=x, y=y, z=z))
    m.scale = Vector3(x=float(scale[0]), y=float(scale[1]), z=float(scale[2]))
    m.color = ColorRGBA(r=rgba[0], g=rgba[1], b=rgba[2], a=rgba[3])
    return m


def twin_markers(normal: ArrayLike, stamp: Any, sphere_position_m: ArrayLike | None = None,
                 beam_z_m: ArrayLike | None = None, beam_phi_rad: ArrayLike | None = None,
                 ) -> Any:
    """MarkerArray of the twin.

    Parameters
    ----------
    normal : ndarray, shape (3,)
        Surface normal (orients sphere and mirror where no quaternion is known).
    stamp : builtin_interfaces.msg.Time
    sphere_position_m : ndarray, shape (3,), optional
        Full-sphere centre; on the tips' nominal height if omitted.
    beam_z_m, beam_phi_rad : ndarray, shape (4,), optional
        Beam coordinates; beams drawn flat at z = 0 if omitted.
    """
    centre = np.zeros(3) if sphere_position_m is None else np.asarray(sphere_position_m)
    q = _quaternion_from_normal(np.asarray(normal, dtype=float))
    out = MarkerArray()
    out.markers.append(_marker(0, Marker.SPHERE, stamp, centre, q, [2 * SPHERE_RADIUS_M] * 3,
                               (0.6, 0.6, 0.65, 0.6)))
    out.markers.append(_marker(1, Marker.CYLINDER, stamp, centre, q,
                               [2 * FACE_RADIUS_M, 2 * FACE_RADIUS_M, FACE_THICKNESS_M],
                               (0.2, 0.6, 1.0, 1.0)))
    z = np.zeros(4) if beam_z_m is None else np.asarray(beam_z_m)
    phi = np.zeros(4) if beam_phi_rad is None else np.asarray(beam_phi_rad)
    for k in range(4):
        # Beam k's suspension lies at polar angle 180 deg - k * 90 deg; the beam points inwards.
        angle = math.pi - k * 0.5 * math.pi
        inward = -np.array([math.cos(angle), math.sin(angle), 0.0])
        base = -inward * BEAM_SUSPENSION_RADIUS_M + np.array([0.0, 0.0, z[k]])
        mid = base + 0.5 * BEAM_LENGTH_M * np.array([inward[0] * math.cos(phi[k]),
                                                     inward[1] * math.cos(phi[k]),
                                                     math.sin(phi[k])])
        yaw = math.atan2(inward[1], inward[0])
        pitch = -phi[k]
        qb = np.array([math.cos(yaw / 2) * math.cos(pitch / 2),
                       -math.sin(yaw / 2) * math.sin(pitch / 2),
                       math.cos(yaw / 2) * math.sin(pitch / 2),
                       math.sin(yaw / 2) * math.cos(pitch / 2)])
        out.markers.append(_marker(2 + k, Marker.CUBE, stamp, mid, qb,
                                   [BEAM_LENGTH_M, BEAM_WIDTH_M, BEAM_THICKNESS_M],
                                   (0.85, 0.55, 0.2, 1.0)))
    out.markers.append(_normal_arrow(6, stamp, centre, np.asarray(normal, dtype=float)))
    return out


def reference_markers(reference_normal: ArrayLike, stamp: Any) -> Any:
    """MarkerArray of the reference normal: an arrow from the sphere's nominal centre, in a
    namespace of its own, so that it sits beside the simulator's markers on the same topic."""
    out = MarkerArray()
    out.markers.append(_normal_arrow(0, stamp, NOMINAL_CENTRE_M,
                                     np.asarray(reference_normal, dtype=float),
                                     REFERENCE_RGBA, REFERENCE_NAMESPACE))
    return out


def _normal_arrow(marker_id: int, stamp: Any, centre: NDArray[np.float64],
                  normal: NDArray[np.float64],
                  rgba: tuple[float, float, float, float] = (0.9, 0.9, 0.2, 1.0),
                  namespace: str = NAMESPACE) -> Any:
    """A normal as an arrow from the sphere's centre (RViz has no display for a
    Vector3Stamped)."""
    arrow = _marker(marker_id, Marker.ARROW, stamp, np.zeros(3), np.array([1.0, 0, 0, 0]),
                    [NORMAL_ARROW_SHAFT_M, 2 * NORMAL_ARROW_SHAFT_M, 0.0], rgba)
    arrow.ns = namespace
    tip = centre + NORMAL_ARROW_LENGTH_M * normal / np.linalg.norm(normal)
    arrow.points = [Point(x=float(a), y=float(b), z=float(c)) for a, b, c in (centre, tip)]
    return arrow
