"""The sphere's pose on /tf is the pose /sphere/state carries (world -> sphere)."""

import numpy as np
import pytest

from msg_defs.conversions import sphere_state_from_msg, sphere_state_to_msg, time_from_ns
from msg_defs.topics import SPHERE_FRAME, WORLD_FRAME
from msg_defs.transforms import sphere_transform_msg
from sphere_sim.model.rotations import cardan_to_quat


def test_the_transform_carries_the_odometrys_pose_in_the_same_frames():
    q = cardan_to_quat(0.2, -0.1, 0.05) * 3.0  # not normalised: both normalise it
    position_m, stamp = [1e-6, -2e-6, 8.5e-4], time_from_ns(1_250_000_000)
    transform = sphere_transform_msg(position_m, q, stamp)
    odometry = sphere_state_to_msg(position_m, q, np.zeros(3), np.zeros(3), stamp=stamp)
    assert (transform.header.frame_id, transform.child_frame_id) == (WORLD_FRAME, SPHERE_FRAME)
    assert transform.header.stamp == odometry.header.stamp
    t, r = transform.transform.translation, transform.transform.rotation
    position, quaternion = sphere_state_from_msg(odometry)
    np.testing.assert_allclose([t.x, t.y, t.z], position, rtol=0, atol=0)
    np.testing.assert_allclose([r.w, r.x, r.y, r.z], quaternion, rtol=0, atol=1e-16)
    assert np.linalg.norm([r.w, r.x, r.y, r.z]) == pytest.approx(1.0, abs=1e-15)


@pytest.mark.parametrize('bad', [[0.0, 0.0, 0.0, 0.0], [1.0, np.nan, 0.0, 0.0]],
                         ids=['zero', 'nan'])
def test_a_quaternion_that_is_no_rotation_is_refused(bad):
    with pytest.raises(ValueError, match='quaternion'):
        sphere_transform_msg([0.0, 0.0, 0.0], bad, time_from_ns(0))
