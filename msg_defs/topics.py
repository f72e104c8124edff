"""The topic contract: every topic's name, message type, QoS, frame and units.

Nodes, the recorder and the tests take these from here and nowhere else. All quantities are
SI. Beams are numbered 1..4 as in the physics model; the joint names below carry that number.

Encodings that the message types leave open
-------------------------------------------
Beam state (``/beams/state``, sensor_msgs/JointState)
    Each beam has two degrees of freedom, the height z of its suspension point and its tilt
    phi, so it appears as two joints, beam-major: ``beam_1_z, beam_1_phi, beam_2_z, ...``
    (:data:`BEAM_STATE_JOINT_NAMES`). ``position`` holds z in m for ``*_z`` joints and phi in
    rad for ``*_phi`` joints; ``velocity`` holds their rates (m/s, rad/s) or is empty;
    ``effort`` is empty.
Beam voltages (``/beams/voltage``, ``/beams/voltage_command``, sensor_msgs/JointState)
    One joint per beam, ``beam_1 .. beam_4`` (:data:`BEAM_NAMES`), in any order; the voltage
    in V is in ``effort``, ``position`` and ``velocity`` are empty.
Pulse programme (``/beams/pulse_program``, trajectory_msgs/JointTrajectory)
    ``joint_names`` are :data:`BEAM_NAMES`; each point's ``effort`` holds the beam voltages
    in V from its ``time_from_start`` until the next point's (zero-order hold, the last
    point's voltages hold until the programme is replaced). ``header.stamp`` is when the
    programme starts.
Programme status (``/beams/programme_status``, action_msgs/GoalStatusArray)
    Each received programme is a goal, one status per event. ``goal_info.goal_id.uuid`` names
    the programme and is the same in all its events: bytes 0-7 the stamp it was sent with (the
    start it asked for) in ns, bytes 8-15 the receiver's count of programmes, each a
    big-endian unsigned 64-bit integer. ``goal_info.stamp`` is the simulated time of the event
    (the message has no header, and this is the one stamp a status has): EXECUTING when it
    started, SUCCEEDED when its last segment ended, CANCELED when a later command cut it,
    ABORTED when refused. Kick cycles are timed from these, not from the start asked for. A
    status has no text: the simulator reports refusals with their reasons, and cuts by a
    voltage command, on ``/diagnostics`` (ten a second, the rest counted); a cut by a later
    programme is that programme's start. Until 2026-11-27 this was
    actionlib_msgs/GoalStatusArray (``header.stamp`` the event's time, ``goal_id.stamp`` the
    start asked for, ``goal_id.id`` the count as text, ``text`` why);
    :func:`msg_defs.conversions.programme_events_from_msg` still reads those bags.
Sphere state (``/sphere/state``, nav_msgs/Odometry)
    Pose of the sphere frame ``sphere`` in ``world``: the sphere centre in m and the
    orientation quaternion; the twist (m/s, rad/s) is expressed in ``sphere`` as the message
    definition requires.
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING

from action_msgs.msg import GoalStatusArray
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import Vector3Stamped
from nav_msgs.msg import Odometry
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory
from visualization_msgs.msg import MarkerArray

# The device's constants belong to the contract too; their home is the ROS-free msg_defs.device.
from msg_defs.device import BEAM_COUNT as BEAM_COUNT
from msg_defs.device import BEAM_IDS as BEAM_IDS
from msg_defs.device import NS_PER_S as NS_PER_S
from msg_defs.device import VOLTAGE_LIMIT_V as VOLTAGE_LIMIT_V

if TYPE_CHECKING:
    from rclpy.qos import QoSProfile

WORLD_FRAME = 'world'
SPHERE_FRAME = 'sphere'

BEAM_NAMES = tuple(f'beam_{k}' for k in BEAM_IDS)
BEAM_DOFS = ('z', 'phi')
BEAM_STATE_JOINT_NAMES = tuple(f'{beam}_{dof}' for beam in BEAM_NAMES for dof in BEAM_DOFS)


@dataclasses.dataclass(frozen=True)
class QosSpec:
    """A QoS profile as plain data (history is always keep-last).

    Attributes
    ----------
    depth : int
        History depth.
    reliable : bool
        Reliable (True) or best-effort (False) delivery.
    transient_local : bool
        Whether late-joining subscribers receive the last ``depth`` messages.
    """

    depth: int
    reliable: bool = True
    transient_local: bool = False

    def to_profile(self, min_depth: int = 0) -> QoSProfile:
        """The equivalent ``rclpy.qos.QoSProfile``; a subscriber that takes messages in bursts
        (a recorder, a test probe) asks for a history of at least ``min_depth``, which does
        not affect QoS compatibility.

        rclpy is imported here rather than at module level so that the contract can be read
        by tools that never join a ROS graph (the CLI, the process supervisor, analysis).
        """
        from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

        return QoSProfile(
            history=HistoryPolicy.KEEP_LAST,
            depth=max(self.depth, min_depth),
            reliability=(ReliabilityPolicy.RELIABLE if self.reliable
                         else ReliabilityPolicy.BEST_EFFORT),
            durability=(DurabilityPolicy.TRANSIENT_LOCAL if self.transient_local
                        else DurabilityPolicy.VOLATILE),
        )


# Streams and commands: reliable, so a recorder or a test sees every message on localhost.
STREAM_QOS = QosSpec(depth=10)
# Commands to the simulator: deep enough that a burst of COMMAND_BURST_LIMIT commands within
# a second is held whole while the simulator integrates, so that each one is applied, refused
# or counted as dropped, never lost in silence. Measured with Fast DDS 2.14 (rmw_fastrtps,
# Jazzy), 10 000 JointState sent in 0.3-0.7 s: a keep-last reader of depth 10 took 553 and
# the QoS event message_lost said 0, since a reader's own history replaces its oldest sample
# without a word; message_lost counts only what the sender's history gave up before this
# reader had it (a depth-10 sender to a depth-10 000 reader: 5 013 taken, 4 987 reported
# lost). The simulator counts those through the event and keeps its own queue this deep; a
# keep-all reader instead held Fast DDS's resource limit and left the rest to retransmission
# (3 821 of 10 000 taken in 20 s). Both ends use this profile, so a sender of the contract
# does not give up a burst of that size either. A JointState of four beams is about 200
# bytes: a full queue costs a few MB, only while a burst waits.
COMMAND_BURST_LIMIT = 10_000
COMMAND_QOS = QosSpec(depth=COMMAND_BURST_LIMIT)
# References stay valid until replaced, so late joiners get the current one.
LATCHED_QOS = QosSpec(depth=1, transient_local=True)
# rclpy's and rclcpp's time sources subscribe to /clock best-effort with depth 1.
CLOCK_QOS = QosSpec(depth=1, reliable=False)


@dataclasses.dataclass(frozen=True)
class Topic:
    """One topic of the contract.

    Attributes
    ----------
    name : str
        Absolute topic name.
    msg_type : type
        Message class.
    qos : QosSpec
        QoS every publisher and subscriber uses.
    frame_id : str
        ``header.frame_id`` of the messages, '' where the message has no frame.
    units : str
        Units of the payload fields.
    description : str
        What the topic carries and who publishes it.
    """

    name: str
    msg_type: type
    qos: QosSpec
    frame_id: str
    units: str
    description: str


SURFACE_NORMAL = Topic(
    name='/sphere/surface_normal',
    msg_type=Vector3Stamped,
    qos=STREAM_QOS,
    frame_id=WORLD_FRAME,
    units='1 (unit vector)',
    description='Unit normal of the sphere\'s flattened mirror face; published by the simulator.',
)
SPHERE_STATE = Topic(
    name='/sphere/state',
    msg_type=Odometry,
    qos=STREAM_QOS,
    frame_id=WORLD_FRAME,
    units='m, quaternion, m/s, rad/s',
    description=f'Full rigid-body state of the sphere; child frame \'{SPHERE_FRAME}\'.',
)
BEAM_STATE = Topic(
    name='/beams/state',
    msg_type=JointState,
    qos=STREAM_QOS,
    frame_id='',
    units='m and rad (position), m/s and rad/s (velocity)',
    description='Height z and tilt phi of each beam, joints beam_k_z and beam_k_phi.',
)
BEAM_VOLTAGE = Topic(
    name='/beams/voltage',
    msg_type=JointState,
    qos=STREAM_QOS,
    frame_id='',
    units='V (effort)',
    description='Voltages the simulator applies to beam_1..beam_4.',
)
VOLTAGE_COMMAND = Topic(
    name='/beams/voltage_command',
    msg_type=JointState,
    qos=COMMAND_QOS,
    frame_id='',
    units='V (effort)',
    description='Voltages requested for beam_1..beam_4; held until the next command.',
)
PULSE_PROGRAM = Topic(
    name='/beams/pulse_program',
    msg_type=JointTrajectory,
    # Not latched: a programme is a one-off kick, and a simulator (re)joining late must not
    # replay the last one.
    qos=COMMAND_QOS,
    frame_id='',
    units='V (effort), s (time_from_start)',
    description='Piecewise-constant voltage programme for beam_1..beam_4.',
)
PROGRAMME_STATUS = Topic(
    name='/beams/programme_status',
    msg_type=GoalStatusArray,
    qos=STREAM_QOS,
    frame_id='',
    units='s (stamps, simulated time)',
    description='Each pulse programme\'s actual start and end, or its cut or refusal; '
                'published by the simulator.',
)
SPHERE_REFERENCE = Topic(
    name='/sphere/reference',
    msg_type=Vector3Stamped,
    qos=LATCHED_QOS,
    frame_id=WORLD_FRAME,
    units='1 (unit vector)',
    description='Surface normal the controller should reach.',
)
CONTROLLER_STATUS = Topic(
    name='/controller/status',
    msg_type=DiagnosticArray,
    qos=STREAM_QOS,
    frame_id='',
    units='-',
    description='Health and mode of the running controller, one status per controller.',
)
DIAGNOSTICS = Topic(
    name='/diagnostics',
    msg_type=DiagnosticArray,
    qos=STREAM_QOS,
    frame_id='',
    units='-',
    description='Rejected commands and plant health from the simulator (the ROS convention '
                'for diagnostics, so rqt_runtime_monitor and Foxglove show them).',
)
MARKERS = Topic(
    name='/twin/markers',
    msg_type=MarkerArray,
    qos=STREAM_QOS,
    frame_id=WORLD_FRAME,
    units='m',
    description='Mirror, sphere, beams and measured normal (simulator) and the reference '
                'normal (reference node) as markers for RViz or Foxglove.',
)
CLOCK = Topic(
    name='/clock',
    msg_type=Clock,
    qos=CLOCK_QOS,
    frame_id='',
    units='s (simulated time)',
    description='Simulated time, published by the simulator when use_sim_time is wanted.',
)

ALL_TOPICS = (
    SURFACE_NORMAL,
    SPHERE_STATE,
    BEAM_STATE,
    BEAM_VOLTAGE,
    VOLTAGE_COMMAND,
    PULSE_PROGRAM,
    PROGRAMME_STATUS,
    SPHERE_REFERENCE,
    CONTROLLER_STATUS,
    DIAGNOSTICS,
    MARKERS,
    CLOCK,
)


def topic_by_name(name: str) -> Topic:
    """The :class:`Topic` called ``name``.

    Raises
    ------
    KeyError
        If the contract has no such topic.
    """
    for topic in ALL_TOPICS:
        if topic.name == name:
            return topic
    raise KeyError(f'no topic {name!r} in the contract; known: '
                   + ', '.join(t.name for t in ALL_TOPICS))
