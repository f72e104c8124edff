"""The MarkerArray of the twin: sphere, mirror face and four beams, to scale, in world."""

import math

import numpy as np
import pytest
from builtin_interfaces.msg import Time

from msg_defs.markers import (
    BEAM_LENGTH_M,
    NOMINAL_CENTRE_M,
    NORMAL_ARROW_LENGTH_M,
    SPHERE_RADIUS_M,
    reference_markers,
    twin_markers,
)
from msg_defs.topics import WORLD_FRAME
from sphere_sim.kicks.discrete import normal_from_xy
from sphere_sim.model.rotations import quat_to_matrix


def _quat(marker):
    o = marker.pose.orientation
    return np.array([o.w, o.x, o.y, o.z])


def test_mirror_face_points_along_the_normal_and_the_sphere_sits_at_its_centre():
    normal = normal_from_xy(0.3, -0.2)
    centre = np.array([1e-6, -2e-6, 0.8e-3])
    markers = twin_markers(normal, Time(sec=3), sphere_position_m=centre).markers
    assert [m.id for m in markers] == list(range(7))
    assert all(m.header.frame_id == WORLD_FRAME and m.header.stamp.sec == 3 for m in markers)
    sphere, face = markers[0], markers[1]
    np.testing.assert_allclose([sphere.pose.position.x, sphere.pose.position.y,
                                sphere.pose.position.z], centre)
    assert sphere.scale.x == 2 * SPHERE_RADIUS_M
    # The cylinder's axis (+z of the marker) is the surface normal.
    np.testing.assert_allclose(quat_to_matrix(_quat(face))[:, 2], normal, atol=1e-12)
    # The arrow runs from the centre along the normal, its length to scale.
    tail, tip = (np.array([p.x, p.y, p.z]) for p in markers[6].points)
    np.testing.assert_allclose(tail, centre)
    np.testing.assert_allclose((tip - tail) / NORMAL_ARROW_LENGTH_M, normal, atol=1e-12)


def test_beams_point_inwards_and_tilt_with_phi():
    phi = np.array([0.0, 0.01, 0.0, -0.02])
    markers = twin_markers(np.array([0.0, 0.0, 1.0]), Time(), beam_z_m=np.zeros(4),
                           beam_phi_rad=phi).markers[2:6]
    for k, marker in enumerate(markers):
        axis = quat_to_matrix(_quat(marker))[:, 0]  # the box's long side
        angle = math.pi - k * 0.5 * math.pi  # beam k + 1's suspension, clockwise from the left
        inward = -np.array([math.cos(angle), math.sin(angle)])
        np.testing.assert_allclose(axis[:2] / np.hypot(*axis[:2]), inward, atol=1e-12)
        assert abs(math.asin(axis[2]) - phi[k]) < 1e-12
        assert marker.scale.x == BEAM_LENGTH_M


def test_the_reference_arrow_has_a_namespace_of_its_own_and_points_along_the_reference():
    reference = normal_from_xy(-0.1, 0.2)
    (arrow,) = reference_markers(reference, Time(sec=7)).markers
    simulator_namespaces = {m.ns for m in twin_markers(reference, Time()).markers}
    assert arrow.ns not in simulator_namespaces and arrow.header.frame_id == WORLD_FRAME
    tail, tip = (np.array([p.x, p.y, p.z]) for p in arrow.points)
    np.testing.assert_allclose(tail, NOMINAL_CENTRE_M)
    np.testing.assert_allclose((tip - tail) / NORMAL_ARROW_LENGTH_M, reference, atol=1e-12)
    # The nominal centre is a level sphere's, resting on tips 0.4 mm from the axis.
    assert np.hypot(0.4e-3, NOMINAL_CENTRE_M[2]) == pytest.approx(SPHERE_RADIUS_M)
