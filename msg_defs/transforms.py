"""The sphere's pose on ``/tf`` (``world`` -> ``sphere``), where ``tf2_msgs`` is installed.

A system ROS has ``tf2_msgs``; the PyPI wheels of ROS 2 do not, so ``/tf`` is optional: without
it the pose is ``/sphere/state`` (nav_msgs/Odometry with the same frames, the same pose), and
the simulator says so once at start-up.
"""

from __future__ import annotations

from typing import Any

from numpy.typing import ArrayLike

from msg_defs.conversions import finite_vector, unit_quaternion
from msg_defs.topics import SPHERE_FRAME, WORLD_FRAME

TF_TOPIC = '/tf'
# tf2's own publishers use a reliable, volatile queue of this depth.
TF_QUEUE_DEPTH = 100
NO_TF_LINE = (f'tf2_msgs is not installed: no {TF_TOPIC}; the sphere\'s pose ({WORLD_FRAME} -> '
              f'{SPHERE_FRAME}) is on /sphere/state (nav_msgs/Odometry)')


def tf_message_type() -> Any | None:
    """``tf2_msgs/TFMessage``, or None where that package is not installed."""
    try:
        from tf2_msgs.msg import TFMessage
    except ImportError:
        return None
    return TFMessage


def sphere_transform_msg(position_m: ArrayLike, quaternion_wxyz: ArrayLike, stamp: Any) -> Any:
    """``geometry_msgs/TransformStamped`` of ``sphere`` in ``world``: the pose that
    ``/sphere/state`` carries (the quaternion normalised here)."""
    from geometry_msgs.msg import TransformStamped

    q = unit_quaternion(quaternion_wxyz)
    p = finite_vector(position_m, 3, 'position')
    msg = TransformStamped()
    msg.header.stamp = stamp
    msg.header.frame_id = WORLD_FRAME
    msg.child_frame_id = SPHERE_FRAME
    t, r = msg.transform.translation, msg.transform.rotation
    t.x, t.y, t.z = map(float, p)
    r.w, r.x, r.y, r.z = map(float, q)
    return msg
