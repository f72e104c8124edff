"""numpy <-> message conversions for the topics of :mod:`msg_defs.topics`.

Functions named ``*_to_msg`` build a message from arrays, ``*_from_msg`` read one back.
Both validate the encoding: a message that does not follow the contract (names, lengths,
frames, finite numbers) raises ``ValueError`` saying what is wrong, so a node can log it and
drop the message instead of acting on it. The rules of a beam command itself (limits, time
order, the last segment off: :mod:`msg_defs.voltage_rules`) are checked once where it enters
something: here by a sender, in the twin by the receiver. No rclpy here; stamps are
``builtin_interfaces/Time`` (a node passes ``self.get_clock().now().to_msg()``).
"""

import functools
from collections.abc import Callable, Iterable
from typing import Any

import numpy as np
from action_msgs.msg import GoalInfo, GoalStatus, GoalStatusArray
from builtin_interfaces.msg import Duration, Time
from geometry_msgs.msg import Vector3Stamped
from nav_msgs.msg import Odometry
from numpy.typing import ArrayLike, NDArray
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint
from unique_identifier_msgs.msg import UUID

from msg_defs.device import BEAM_COUNT, NS_PER_S, VOLTAGE_LIMIT_V
from msg_defs.programme_events import ProgrammeEvent, ProgrammeState
from msg_defs.topics import BEAM_NAMES, BEAM_STATE_JOINT_NAMES, SPHERE_FRAME, WORLD_FRAME
from msg_defs.voltage_rules import check_segments, check_voltages, finite_vector

# A published normal is a float64 unit vector; anything further from length 1 than this did
# not come from a normalised rotation and is rejected.
UNIT_NORM_TOLERANCE = 1e-6



def time_from_ns(stamp_ns: int) -> Any:
    """``builtin_interfaces/Time`` for a time in integer nanoseconds (>= 0)."""
    stamp_ns = int(stamp_ns)
    if stamp_ns < 0:
        raise ValueError(f'stamp must be >= 0 ns, got {stamp_ns}')
    sec, nanosec = divmod(stamp_ns, NS_PER_S)
    return Time(sec=sec, nanosec=nanosec)


def ns_from_time(stamp: Any) -> int:
    """Integer nanoseconds of a ``builtin_interfaces/Time``."""
    return stamp.sec * NS_PER_S + stamp.nanosec


def status_values(status: Any) -> dict[str, str]:
    """The key-values of a ``diagnostic_msgs/DiagnosticStatus`` as a dict of strings."""
    return {kv.key: kv.value for kv in status.values}


def _unit_vector(values: ArrayLike, what: str) -> NDArray[np.float64]:
    vector = finite_vector(values, 3, what)
    norm = float(np.linalg.norm(vector))
    if abs(norm - 1.0) > UNIT_NORM_TOLERANCE:
        raise ValueError(f'{what}: expected a unit vector, got length {norm:.9g}')
    return vector


def _stamp_or_zero(stamp: Any) -> Any:
    return Time() if stamp is None else stamp


# --- surface normal (geometry_msgs/Vector3Stamped) ----------------------------------------

def surface_normal_to_msg(normal: ArrayLike, stamp: Any = None,
                          frame_id: str = WORLD_FRAME) -> Any:
    """Message for ``/sphere/surface_normal`` (or ``/sphere/reference``).

    Parameters
    ----------
    normal : array_like, shape (3,)
        Unit surface normal in ``frame_id``.
    stamp : builtin_interfaces.msg.Time, optional
        Header stamp; time 0 if omitted.
    frame_id : str
        Frame the vector is expressed in.

    Returns
    -------
    geometry_msgs.msg.Vector3Stamped

    Raises
    ------
    ValueError
        If ``normal`` is not a finite unit vector of length 3.
    """
    x, y, z = _unit_vector(normal, 'surface normal')
    msg = Vector3Stamped()
    msg.header.stamp = _stamp_or_zero(stamp)
    msg.header.frame_id = frame_id
    msg.vector.x, msg.vector.y, msg.vector.z = float(x), float(y), float(z)
    return msg


def surface_normal_from_msg(msg: Any, frame_id: str = WORLD_FRAME) -> NDArray[np.float64]:
    """The unit normal carried by a ``Vector3Stamped``.

    Parameters
    ----------
    msg : geometry_msgs.msg.Vector3Stamped
    frame_id : str
        Frame the vector must be expressed in.

    Returns
    -------
    ndarray, shape (3,)

    Raises
    ------
    ValueError
        If the frame differs from ``frame_id`` or the vector is not a finite unit vector.
    """
    if msg.header.frame_id != frame_id:
        raise ValueError(f'surface normal: expected frame_id {frame_id!r}, '
                         f'got {msg.header.frame_id!r}')
    return _unit_vector((msg.vector.x, msg.vector.y, msg.vector.z), 'surface normal')


# --- beam voltages (sensor_msgs/JointState, volts in effort) ------------------------------

def voltages_to_msg(voltages_v: ArrayLike, stamp: Any = None,
                    max_abs_voltage_v: float = VOLTAGE_LIMIT_V) -> Any:
    """Message for ``/beams/voltage_command`` or ``/beams/voltage``.

    Parameters
    ----------
    voltages_v : array_like, shape (4,)
        Voltage of beam 1..4 (V).
    stamp : builtin_interfaces.msg.Time, optional
        Header stamp; time 0 if omitted.
    max_abs_voltage_v : float
        Largest admissible magnitude (V).

    Returns
    -------
    sensor_msgs.msg.JointState
        Joints ``beam_1 .. beam_4`` with the voltages in ``effort``.

    Raises
    ------
    ValueError
        If the voltages are not 4 finite values within the limit.
    """
    voltages = check_voltages(voltages_v, max_abs_voltage_v)
    msg = JointState()
    msg.header.stamp = _stamp_or_zero(stamp)
    msg.name = list(BEAM_NAMES)
    msg.effort = voltages.tolist()
    return msg


def voltages_from_msg(msg: Any) -> NDArray[np.float64]:
    """Beam voltages of a ``JointState``, in beam order 1..4 whatever the joint order.

    The receiver applies the command's rules (:func:`msg_defs.voltage_rules.check_voltages`).

    Parameters
    ----------
    msg : sensor_msgs.msg.JointState
        Joints ``beam_1 .. beam_4``, each exactly once, voltages in ``effort``.

    Returns
    -------
    ndarray, shape (4,)
        Voltages of beam 1..4 (V).

    Raises
    ------
    ValueError
        On missing, unknown or repeated joint names, an ``effort`` whose length differs from
        the names', or non-finite values.
    """
    names = list(msg.name)
    if sorted(names) != sorted(BEAM_NAMES):
        raise ValueError(f'voltages: expected joint names {list(BEAM_NAMES)} (any order, each '
                         f'once), got {names}')
    effort = list(msg.effort)
    if len(effort) != len(names):
        raise ValueError(f'voltages: {len(names)} joint names but {len(effort)} effort values')
    by_name = dict(zip(names, effort, strict=True))
    return finite_vector([by_name[name] for name in BEAM_NAMES], BEAM_COUNT, 'voltages')


# --- beam state (sensor_msgs/JointState, joints beam_k_z and beam_k_phi) ------------------

def beam_state_to_msg(z_m: ArrayLike, phi_rad: ArrayLike, z_rate_m_per_s: ArrayLike | None = None,
                      phi_rate_rad_per_s: ArrayLike | None = None, stamp: Any = None) -> Any:
    """Message for ``/beams/state``.

    Parameters
    ----------
    z_m, phi_rad : array_like, shape (4,)
        Height (m) and tilt (rad) of beam 1..4.
    z_rate_m_per_s, phi_rate_rad_per_s : array_like, shape (4,), optional
        Their rates; ``velocity`` stays empty unless both are given.
    stamp : builtin_interfaces.msg.Time, optional
        Header stamp; time 0 if omitted.

    Returns
    -------
    sensor_msgs.msg.JointState
        Joints :data:`msg_defs.topics.BEAM_STATE_JOINT_NAMES`, interleaved z, phi per beam.

    Raises
    ------
    ValueError
        If an array is not 4 finite values, or only one of the rates is given.
    """
    msg = JointState()
    msg.header.stamp = _stamp_or_zero(stamp)
    msg.name = list(BEAM_STATE_JOINT_NAMES)
    msg.position = _interleave(z_m, phi_rad, 'beam position').tolist()
    if (z_rate_m_per_s is None) != (phi_rate_rad_per_s is None):
        raise ValueError('beam state: give both rates or neither')
    if z_rate_m_per_s is not None and phi_rate_rad_per_s is not None:  # both, checked above
        msg.velocity = _interleave(z_rate_m_per_s, phi_rate_rad_per_s, 'beam velocity').tolist()
    return msg


def beam_state_from_msg(msg: Any) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Heights and tilts of a ``/beams/state`` message.

    Returns
    -------
    z_m, phi_rad : ndarray, shape (4,)
        Height (m) and tilt (rad) of beam 1..4.

    Raises
    ------
    ValueError
        If the joint names are not exactly :data:`BEAM_STATE_JOINT_NAMES` in that order, or
        the positions are not finite.
    """
    if tuple(msg.name) != BEAM_STATE_JOINT_NAMES:
        raise ValueError(f'beam state: expected joint names {list(BEAM_STATE_JOINT_NAMES)}, '
                         f'got {list(msg.name)}')
    position = finite_vector(msg.position, 2 * BEAM_COUNT, 'beam position')
    return position[0::2].copy(), position[1::2].copy()


def beam_rates_from_msg(msg: Any) -> tuple[NDArray[np.float64], NDArray[np.float64]] | None:
    """The rates (m/s, rad/s) of beam 1..4 in a ``/beams/state`` message, or None where it
    carries none (``velocity`` empty).

    Raises
    ------
    ValueError
        If the rates are not finite, or not one per joint.
    """
    if len(msg.velocity) == 0:
        return None
    velocity = finite_vector(msg.velocity, 2 * BEAM_COUNT, 'beam velocity')
    return velocity[0::2].copy(), velocity[1::2].copy()


def _interleave(z_values: ArrayLike, phi_values: ArrayLike, what: str) -> NDArray[np.float64]:
    joined = np.empty(2 * BEAM_COUNT)
    joined[0::2] = finite_vector(z_values, BEAM_COUNT, f'{what} z')
    joined[1::2] = finite_vector(phi_values, BEAM_COUNT, f'{what} phi')
    return joined


# --- pulse programme (trajectory_msgs/JointTrajectory, volts in effort) -------------------

def programme_to_msg(times_s: ArrayLike, voltages_v: Iterable[ArrayLike], stamp: Any = None,
                     max_abs_voltage_v: float = VOLTAGE_LIMIT_V) -> Any:
    """Message for ``/beams/pulse_program`` from zero-order-hold segments.

    Parameters
    ----------
    times_s : array_like, shape (n,)
        Start of each segment relative to ``stamp`` (s), >= 0 and strictly increasing.
    voltages_v : array_like, shape (n, 4)
        Voltages of beam 1..4 (V) from each start until the next.
    stamp : builtin_interfaces.msg.Time, optional
        When the programme starts; time 0 (start on receipt) if omitted.

    Raises
    ------
    ValueError
        If the segments break the contract (see :func:`programme_from_msg`).
    """
    times, volts = check_segments(times_s, voltages_v, max_abs_voltage_v)
    msg = JointTrajectory()
    msg.header.stamp = _stamp_or_zero(stamp)
    msg.joint_names = list(BEAM_NAMES)
    for t, row in zip(times, volts, strict=True):
        point = JointTrajectoryPoint()
        sec, nanosec = divmod(round(t * NS_PER_S), NS_PER_S)
        point.time_from_start = Duration(sec=int(sec), nanosec=int(nanosec))
        point.effort = row.tolist()
        msg.points.append(point)
    return msg


def programme_from_msg(msg: Any) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Segments of a ``/beams/pulse_program`` message, beams in order 1..4.

    The receiver applies the programme's rules (:func:`msg_defs.voltage_rules.check_segments`:
    limits, time order, the last segment off).

    Returns
    -------
    times_s : ndarray, shape (n,)
    voltages_v : ndarray, shape (n, 4)

    Raises
    ------
    ValueError
        On joint names other than ``beam_1 .. beam_4`` (any order, each once), no points, a
        point whose ``effort`` length differs from the names', or non-finite values.
    """
    names = list(msg.joint_names)
    if sorted(names) != sorted(BEAM_NAMES):
        raise ValueError(f'pulse programme: expected joint names {list(BEAM_NAMES)} (any '
                         f'order, each once), got {names}')
    if not msg.points:
        raise ValueError('pulse programme: no points')
    order = [names.index(name) for name in BEAM_NAMES]
    times: list[float] = []
    rows: list[NDArray[np.float64]] = []
    for i, point in enumerate(msg.points):
        effort = list(point.effort)
        if len(effort) != len(names):
            raise ValueError(f'pulse programme: point {i} has {len(effort)} effort values for '
                             f'{len(names)} joints')
        times.append(point.time_from_start.sec
                     + point.time_from_start.nanosec / NS_PER_S)
        rows.append(finite_vector([effort[k] for k in order], BEAM_COUNT,
                                   f'pulse programme point {i}'))
    return np.array(times), np.array(rows)


# --- sphere state (nav_msgs/Odometry) -----------------------------------------------------

def unit_quaternion(quaternion_wxyz: ArrayLike) -> NDArray[np.float64]:
    """``quaternion_wxyz`` normalised; ValueError if it is not finite or has zero length."""
    q = finite_vector(quaternion_wxyz, 4, 'quaternion')
    norm = float(np.linalg.norm(q))
    if norm == 0.0:
        raise ValueError('quaternion: zero length')
    return q / norm


def sphere_state_to_msg(position_m: ArrayLike, quaternion_wxyz: ArrayLike,
                        velocity_m_per_s: ArrayLike, omega_body_rad_per_s: ArrayLike,
                        stamp: Any = None) -> Any:
    """Message for ``/sphere/state``.

    Parameters
    ----------
    position_m : array_like, shape (3,)
        Full-sphere centre in ``world`` (m).
    quaternion_wxyz : array_like, shape (4,)
        Orientation of ``sphere`` in ``world``, scalar first (normalised here).
    velocity_m_per_s : array_like, shape (3,)
        Centre velocity in ``world`` (m/s); expressed in ``sphere`` in the message, as
        nav_msgs/Odometry requires.
    omega_body_rad_per_s : array_like, shape (3,)
        Angular velocity in ``sphere`` (rad/s).
    """
    q = unit_quaternion(quaternion_wxyz)
    p = finite_vector(position_m, 3, 'position')
    v_world = finite_vector(velocity_m_per_s, 3, 'velocity')
    w = finite_vector(omega_body_rad_per_s, 3, 'angular velocity')
    # v_body = R(q)^T v_world, with R(q) v = v + 2 u x (u x v + w v) for q = (w, u).
    u = -q[1:]  # the conjugate rotates world vectors into the body
    v_body = v_world + 2.0 * np.cross(u, np.cross(u, v_world) + q[0] * v_world)
    msg = Odometry()
    msg.header.stamp = _stamp_or_zero(stamp)
    msg.header.frame_id = WORLD_FRAME
    msg.child_frame_id = SPHERE_FRAME
    pose = msg.pose.pose
    pose.position.x, pose.position.y, pose.position.z = map(float, p)
    pose.orientation.w, pose.orientation.x, pose.orientation.y, pose.orientation.z = map(
        float, q)
    twist = msg.twist.twist
    twist.linear.x, twist.linear.y, twist.linear.z = map(float, v_body)
    twist.angular.x, twist.angular.y, twist.angular.z = map(float, w)
    return msg


def sphere_state_from_msg(msg: Any) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(position_m, quaternion_wxyz) of a ``/sphere/state`` message."""
    if msg.header.frame_id != WORLD_FRAME or msg.child_frame_id != SPHERE_FRAME:
        raise ValueError(f'sphere state: expected frames {WORLD_FRAME!r} -> {SPHERE_FRAME!r}, '
                         f'got {msg.header.frame_id!r} -> {msg.child_frame_id!r}')
    pose = msg.pose.pose
    position = finite_vector((pose.position.x, pose.position.y, pose.position.z), 3,
                              'position')
    o = pose.orientation
    return position, finite_vector((o.w, o.x, o.y, o.z), 4, 'quaternion')


def sphere_twist_from_msg(msg: Any) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(velocity_m_per_s in ``world``, omega_body_rad_per_s) of a ``/sphere/state`` message:
    what :func:`sphere_state_to_msg` was given (the message carries the velocity in
    ``sphere``, as nav_msgs/Odometry requires)."""
    _, q = sphere_state_from_msg(msg)
    q = unit_quaternion(q)
    twist = msg.twist.twist
    v_body = finite_vector((twist.linear.x, twist.linear.y, twist.linear.z), 3, 'velocity')
    omega = finite_vector((twist.angular.x, twist.angular.y, twist.angular.z), 3,
                          'angular velocity')
    # v_world = R(q) v_body, with R(q) v = v + 2 u x (u x v + w v) for q = (w, u).
    u = q[1:]
    return v_body + 2.0 * np.cross(u, np.cross(u, v_body) + q[0] * v_body), omega


# How a programme's states map onto an action's goal states (the programme is the goal).
_GOAL_STATUS_OF_STATE = {
    ProgrammeState.STARTED: GoalStatus.STATUS_EXECUTING,
    ProgrammeState.ENDED: GoalStatus.STATUS_SUCCEEDED,
    ProgrammeState.CUT: GoalStatus.STATUS_CANCELED,
    ProgrammeState.REFUSED: GoalStatus.STATUS_ABORTED,
}
_STATE_OF_GOAL_STATUS = {v: k for k, v in _GOAL_STATUS_OF_STATE.items()}
_UUID_HALF = 8  # bytes: the asked stamp in ns, then the count, each a big-endian uint64


def programme_uuid(asked_s: float, number: int) -> list[int]:
    """The 16 bytes of ``goal_id.uuid`` that name a programme: the stamp it was sent with in
    ns, then the receiver's count, each a big-endian unsigned 64-bit integer.

    Raises
    ------
    ValueError
        For a count below 0 or beyond 64 bits.
    """
    try:
        count = int(number).to_bytes(_UUID_HALF, 'big')
    except OverflowError:
        raise ValueError(f'programme count {number} does not fit 64 unsigned bits') from None
    return list(round(max(asked_s, 0.0) * NS_PER_S).to_bytes(_UUID_HALF, 'big') + count)


def programme_of_uuid(uuid: Iterable[int]) -> tuple[float, int]:
    """(asked_s, number) of a ``goal_id.uuid`` made by :func:`programme_uuid`."""
    raw = bytes(int(b) for b in uuid)
    if len(raw) != 2 * _UUID_HALF:
        raise ValueError(f'goal id of {len(raw)} bytes, expected {2 * _UUID_HALF}')
    return (int.from_bytes(raw[:_UUID_HALF], 'big') / NS_PER_S,
            int.from_bytes(raw[_UUID_HALF:], 'big'))


def _state_of(status: int, known: dict[int, ProgrammeState]) -> ProgrammeState:
    state = known.get(status)
    if state is None:
        raise ValueError(f'goal status {status} is none of a programme\'s states')
    return state


def programme_event_to_msg(event: ProgrammeEvent) -> Any:
    """Message for ``/beams/programme_status`` from a :class:`ProgrammeEvent`.

    One goal status: ``goal_info.stamp`` is when it happened, ``goal_info.goal_id`` names the
    programme (:func:`programme_uuid`). ``event.text`` is not carried.
    """
    info = GoalInfo(goal_id=UUID(uuid=programme_uuid(event.asked_s, event.number)),
                    stamp=time_from_ns(round(event.time_s * NS_PER_S)))
    return GoalStatusArray(status_list=[
        GoalStatus(goal_info=info, status=_GOAL_STATUS_OF_STATE[event.state])])


def programme_events_from_msg(msg: Any) -> list[ProgrammeEvent]:
    """The :class:`ProgrammeEvent` s a ``/beams/programme_status`` message carries, in the
    contract's action_msgs/GoalStatusArray or the actionlib_msgs one of older bags.

    Raises
    ------
    ValueError
        For a goal status that is not one of the four a programme can be in, or a goal id
        that does not name a programme.
    """
    if hasattr(msg, 'header'):  # only the legacy layout has one
        return _legacy_programme_events(msg)
    events: list[ProgrammeEvent] = []
    for status in msg.status_list:
        asked_s, number = programme_of_uuid(status.goal_info.goal_id.uuid)
        events.append(ProgrammeEvent(_state_of(status.status, _STATE_OF_GOAL_STATUS), asked_s,
                                     number, ns_from_time(status.goal_info.stamp) / NS_PER_S))
    return events


# Until 2026-11-27 the topic was actionlib_msgs/GoalStatusArray, which leaves ROS after Jazzy;
# bags recorded before are still read, by field names, so the package need not be installed.
# Each status was one event: header.stamp its time, goal_id.stamp the start asked for,
# goal_id.id the count as decimal text, status ACTIVE 1, PREEMPTED 2, SUCCEEDED 3, REJECTED 5.
LEGACY_PROGRAMME_STATUS_TYPE = 'actionlib_msgs/msg/GoalStatusArray'
_LEGACY_STATE_OF_STATUS = {1: ProgrammeState.STARTED, 3: ProgrammeState.ENDED,
                           2: ProgrammeState.CUT, 5: ProgrammeState.REFUSED}
# Its ros2msg definition, constants and comments left out (the layout is frozen).
_LEGACY_SCHEMA = f'\n{"=" * 80}\nMSG: '.join((
    'std_msgs/Header header\nGoalStatus[] status_list',
    'actionlib_msgs/GoalStatus\nGoalID goal_id\nuint8 status\nstring text',
    'actionlib_msgs/GoalID\nbuiltin_interfaces/Time stamp\nstring id',
    'std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id',
    'builtin_interfaces/Time\nint32 sec\nuint32 nanosec'))


@functools.cache
def _legacy_decoder() -> Callable[[bytes], Any]:
    from mcap.records import Schema
    from mcap_ros2.decoder import DecoderFactory

    decoder = DecoderFactory().decoder_for('cdr', Schema(
        id=0, name=LEGACY_PROGRAMME_STATUS_TYPE, encoding='ros2msg',
        data=_LEGACY_SCHEMA.encode()))
    assert decoder is not None  # it takes CDR with a ros2msg schema
    return decoder


def legacy_programme_status_from_cdr(data: bytes) -> Any:
    """A recorded (CDR) actionlib_msgs/GoalStatusArray as an object with its field names,
    for :func:`programme_events_from_msg`."""
    return _legacy_decoder()(data)


def _legacy_programme_events(msg: Any) -> list[ProgrammeEvent]:
    time_s = ns_from_time(msg.header.stamp) / NS_PER_S
    events: list[ProgrammeEvent] = []
    for status in msg.status_list:
        state = _state_of(status.status, _LEGACY_STATE_OF_STATUS)
        try:
            number = int(status.goal_id.id)
        except ValueError:
            raise ValueError(f'goal id {status.goal_id.id!r} is not a programme count') from None
        events.append(ProgrammeEvent(state, ns_from_time(status.goal_id.stamp) / NS_PER_S,
                                     number, time_s, status.text))
    return events
