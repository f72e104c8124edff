"""numpy <-> message conversions: exact round trips, and a clear ValueError for bad input."""

import math

import numpy as np
import pytest
from geometry_msgs.msg import Vector3Stamped
from sensor_msgs.msg import JointState

from msg_defs.conversions import (
    beam_state_from_msg,
    beam_state_to_msg,
    ns_from_time,
    surface_normal_from_msg,
    surface_normal_to_msg,
    time_from_ns,
    voltages_from_msg,
    voltages_to_msg,
)
from msg_defs.device import VOLTAGE_LIMIT_V
from msg_defs.topics import BEAM_NAMES, BEAM_STATE_JOINT_NAMES


def _normal_msg(x, y, z, frame_id='world'):
    msg = Vector3Stamped()
    msg.header.frame_id = frame_id
    msg.vector.x, msg.vector.y, msg.vector.z = x, y, z
    return msg


def _voltage_msg(names, effort):
    msg = JointState()
    msg.name = list(names)
    msg.effort = [float(v) for v in effort]
    return msg


# --- time ----------------------------------------------------------------------------------

def test_time_round_trip_splits_seconds_and_nanoseconds():
    stamp = time_from_ns(12_345_678_901)
    assert (stamp.sec, stamp.nanosec) == (12, 345_678_901)
    assert ns_from_time(stamp) == 12_345_678_901
    with pytest.raises(ValueError, match='>= 0'):
        time_from_ns(-1)


# --- surface normal ------------------------------------------------------------------------

def test_surface_normal_round_trip_is_exact():
    normal = np.array([0.48, -0.6, 0.64])
    normal /= np.linalg.norm(normal)
    msg = surface_normal_to_msg(normal, stamp=time_from_ns(2_500_000_000))
    assert msg.header.frame_id == 'world'
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (2, 500_000_000)
    back = surface_normal_from_msg(msg)
    assert back.shape == (3,)
    np.testing.assert_array_equal(back, normal)


@pytest.mark.parametrize(('normal', 'reason'), [
    ([0.0, 0.0, 2.0], 'unit vector'),
    ([0.0, 0.0, 0.0], 'unit vector'),
    ([0.0, 1.0], r'shape \(3,\)'),
    ([[0.0, 0.0, 1.0]], r'shape \(3,\)'),
    ([0.0, math.nan, 1.0], 'finite'),
    ([0.0, 0.0, math.inf], 'finite'),
    (['a', 'b', 'c'], 'not numeric'),
])
def test_surface_normal_to_msg_rejects_non_unit_or_malformed(normal, reason):
    with pytest.raises(ValueError, match=reason):
        surface_normal_to_msg(normal)


def test_surface_normal_from_msg_checks_frame_and_length():
    np.testing.assert_array_equal(surface_normal_from_msg(_normal_msg(0.0, 0.6, 0.8)),
                                  [0.0, 0.6, 0.8])
    with pytest.raises(ValueError, match="frame_id 'world', got 'sphere'"):
        surface_normal_from_msg(_normal_msg(0.0, 0.0, 1.0, frame_id='sphere'))
    with pytest.raises(ValueError, match=r'length 1\.1'):
        surface_normal_from_msg(_normal_msg(0.0, 0.0, 1.1))
    with pytest.raises(ValueError, match='finite'):
        surface_normal_from_msg(_normal_msg(math.nan, 0.0, 1.0))


# --- voltages ------------------------------------------------------------------------------

def test_voltage_round_trip_keeps_beam_order_and_values():
    voltages = np.array([0.0, 12.5, 40.0, VOLTAGE_LIMIT_V])
    msg = voltages_to_msg(voltages, stamp=time_from_ns(7))
    assert list(msg.name) == ['beam_1', 'beam_2', 'beam_3', 'beam_4']
    assert list(msg.effort) == voltages.tolist()
    assert len(msg.position) == len(msg.velocity) == 0
    np.testing.assert_array_equal(voltages_from_msg(msg), voltages)


def test_voltages_from_msg_reorders_joints_to_beam_order():
    msg = _voltage_msg(['beam_3', 'beam_1', 'beam_4', 'beam_2'], [30.0, 10.0, 40.0, 20.0])
    np.testing.assert_array_equal(voltages_from_msg(msg), [10.0, 20.0, 30.0, 40.0])


@pytest.mark.parametrize(('names', 'effort', 'reason'), [
    (['beam_1', 'beam_2', 'beam_3'], [1, 2, 3], 'expected joint names'),
    (['beam_1', 'beam_2', 'beam_3', 'beam_3'], [1, 2, 3, 4], 'expected joint names'),
    (['beam_1', 'beam_2', 'beam_3', 'beam_5'], [1, 2, 3, 4], 'expected joint names'),
    (['beam_1', 'beam_2', 'beam_3', 'beam_4', 'beam_5'], [1, 2, 3, 4, 5],
     'expected joint names'),
    (['beam_1', 'beam_2', 'beam_3', 'beam_4'], [1, 2, 3], '4 joint names but 3 effort'),
    (['beam_1', 'beam_2', 'beam_3', 'beam_4'], [], '4 joint names but 0 effort'),
    (['beam_1', 'beam_2', 'beam_3', 'beam_4'], [1, math.nan, 3, 4], 'finite'),
    (['beam_1', 'beam_2', 'beam_3', 'beam_4'], [1, 2, math.inf, 4], 'finite'),
])
def test_voltages_from_msg_rejects_bad_encodings(names, effort, reason):
    with pytest.raises(ValueError, match=reason):
        voltages_from_msg(_voltage_msg(names, effort))


@pytest.mark.parametrize(('effort', 'reason'), [([1, 2, 3, 80.5], 'exceeds the limit 80 V'),
                                                ([1, 2, 3, -0.5], 'must be >= 0 V')])
def test_a_sender_cannot_put_a_command_beyond_the_rules_on_the_wire(effort, reason):
    with pytest.raises(ValueError, match=reason):
        voltages_to_msg(effort)
    # The receiver reads it (the twin applies the same rules where it enters: test_plants).
    msg = _voltage_msg(list(BEAM_NAMES), effort)
    np.testing.assert_array_equal(voltages_from_msg(msg), effort)


def test_voltage_limit_is_configurable():
    with pytest.raises(ValueError, match='exceeds the limit 4 V'):
        voltages_to_msg([5.0, 5.0, 5.0, 5.0], max_abs_voltage_v=4.0)
    with pytest.raises(ValueError, match='exceeds the limit'):
        voltages_to_msg([0.0, 0.0, 0.0, 100.0])
    with pytest.raises(ValueError, match=r'shape \(4,\)'):
        voltages_to_msg([1.0, 2.0])


# --- beam state ----------------------------------------------------------------------------

def test_beam_state_round_trip_interleaves_z_and_phi():
    z_m = np.array([1e-6, 2e-6, 3e-6, 4e-6])
    phi_rad = np.array([-1e-3, 0.0, 1e-3, 2e-3])
    z_rate = np.array([0.01, 0.02, 0.03, 0.04])
    phi_rate = np.array([-5.0, 5.0, 6.0, 7.0])
    msg = beam_state_to_msg(z_m, phi_rad, z_rate, phi_rate)
    assert tuple(msg.name) == BEAM_STATE_JOINT_NAMES
    assert list(msg.position[:4]) == [1e-6, -1e-3, 2e-6, 0.0]
    assert list(msg.velocity[:4]) == [0.01, -5.0, 0.02, 5.0]
    z_back, phi_back = beam_state_from_msg(msg)
    np.testing.assert_array_equal(z_back, z_m)
    np.testing.assert_array_equal(phi_back, phi_rad)


def test_beam_state_rejects_wrong_names_and_half_rates():
    msg = beam_state_to_msg(np.zeros(4), np.zeros(4))
    assert len(msg.velocity) == 0
    msg.name = list(reversed(msg.name))
    with pytest.raises(ValueError, match='expected joint names'):
        beam_state_from_msg(msg)
    with pytest.raises(ValueError, match='both rates or neither'):
        beam_state_to_msg(np.zeros(4), np.zeros(4), z_rate_m_per_s=np.zeros(4))


def test_programme_round_trip_keeps_segments_to_the_nanosecond():
    from msg_defs.conversions import programme_from_msg, programme_to_msg

    times = np.array([0.0, 6.518267571e-4, 1.0456e-3, 1.2081210929e-3])
    volts = np.array([[35, 35, 0, 0], [35, 35, 80, 80], [35, 35, 0, 0], [0, 0, 0, 0]], float)
    msg = programme_to_msg(times, volts, stamp=time_from_ns(3))
    assert list(msg.joint_names) == ['beam_1', 'beam_2', 'beam_3', 'beam_4']
    back_times, back_volts = programme_from_msg(msg)
    np.testing.assert_allclose(back_times, times, rtol=0, atol=0.5e-9)
    np.testing.assert_array_equal(back_volts, volts)


def test_sphere_state_message_carries_the_body_frame_twist():
    from msg_defs.conversions import sphere_state_from_msg, sphere_state_to_msg

    half = math.radians(30.0)
    q = np.array([math.cos(half), 0.0, 0.0, math.sin(half)])  # 60 deg about z
    msg = sphere_state_to_msg([1e-6, 0.0, 2e-6], q, [1.0, 0.0, 0.0], [0.0, 0.0, 5.0])
    linear = msg.twist.twist.linear
    # World +x seen from a body turned by 60 deg about z.
    np.testing.assert_allclose([linear.x, linear.y, linear.z],
                               [math.cos(2 * half), -math.sin(2 * half), 0.0], atol=1e-15)
    position, quaternion = sphere_state_from_msg(msg)
    np.testing.assert_array_equal(position, [1e-6, 0.0, 2e-6])
    np.testing.assert_allclose(quaternion, q, atol=1e-15)


def test_the_sphere_twist_reads_back_as_it_was_given():
    """A tilted, turned sphere: the world velocity and the body rate come back as given."""
    from msg_defs.conversions import sphere_state_to_msg, sphere_twist_from_msg

    q = np.array([0.9, 0.1, -0.3, 0.2])
    q /= np.linalg.norm(q)
    velocity, omega = np.array([1e-3, -2e-3, 5e-4]), np.array([0.3, -0.1, 2.0])
    back_velocity, back_omega = sphere_twist_from_msg(
        sphere_state_to_msg([0.0, 0.0, 1e-3], q, velocity, omega))
    np.testing.assert_allclose(back_velocity, velocity, rtol=0, atol=1e-18)
    np.testing.assert_array_equal(back_omega, omega)


def test_the_beam_rates_read_back_and_their_absence_is_none():
    from msg_defs.conversions import beam_rates_from_msg, beam_state_to_msg

    z, phi = [1e-7, 2e-7, 3e-7, 4e-7], [1e-3, 2e-3, 3e-3, 4e-3]
    rates = beam_rates_from_msg(beam_state_to_msg(z, phi, [0.1, 0.2, 0.3, 0.4],
                                                  [1.0, 2.0, 3.0, 4.0]))
    assert rates is not None
    np.testing.assert_array_equal(rates[0], [0.1, 0.2, 0.3, 0.4])
    np.testing.assert_array_equal(rates[1], [1.0, 2.0, 3.0, 4.0])
    assert beam_rates_from_msg(beam_state_to_msg(z, phi)) is None


@pytest.mark.parametrize('state', ['started', 'ended', 'cut', 'refused'])
def test_a_programme_report_round_trips_and_names_its_programme_by_its_stamp(state):
    from action_msgs.msg import GoalStatus, GoalStatusArray

    from msg_defs.conversions import programme_event_to_msg, programme_events_from_msg
    from msg_defs.programme_events import ProgrammeEvent, ProgrammeState

    event = ProgrammeEvent(ProgrammeState(state), 12.345678901, 17, 12.36, 'why')
    msg = programme_event_to_msg(event)
    assert isinstance(msg, GoalStatusArray)
    (status,) = msg.status_list
    # The event's time is the status's stamp; the goal id names the programme.
    assert (status.goal_info.stamp.sec, status.goal_info.stamp.nanosec) == (12, 360_000_000)
    assert bytes(status.goal_info.goal_id.uuid) == ((12_345_678_901).to_bytes(8, 'big')
                                                    + (17).to_bytes(8, 'big'))
    assert status.status == {'started': GoalStatus.STATUS_EXECUTING,
                             'ended': GoalStatus.STATUS_SUCCEEDED,
                             'cut': GoalStatus.STATUS_CANCELED,
                             'refused': GoalStatus.STATUS_ABORTED}[state]
    # The text has no field in action_msgs: it is all that does not come back.
    assert programme_events_from_msg(msg) == [event._replace(text='')]


@pytest.mark.parametrize('number', [0, 1, 2**64 - 1])
def test_the_goal_id_carries_the_count_in_its_last_eight_bytes(number):
    from msg_defs.conversions import programme_of_uuid, programme_uuid

    uuid = programme_uuid(0.0, number)
    assert uuid[:8] == [0] * 8 and int.from_bytes(bytes(uuid[8:]), 'big') == number
    assert programme_of_uuid(uuid) == (0.0, number)


@pytest.mark.parametrize('number', [-1, 2**64])
def test_a_count_that_does_not_fit_the_goal_id_is_refused(number):
    from msg_defs.conversions import programme_uuid

    with pytest.raises(ValueError, match='64 unsigned bits'):
        programme_uuid(1.0, number)


@pytest.mark.parametrize('status', [0, 1, 3])  # UNKNOWN, ACCEPTED, CANCELING
def test_a_goal_status_no_programme_is_in_is_refused(status):
    from msg_defs.conversions import programme_event_to_msg, programme_events_from_msg
    from msg_defs.programme_events import ProgrammeEvent, ProgrammeState

    msg = programme_event_to_msg(ProgrammeEvent(ProgrammeState.STARTED, 1.0, 1, 1.0))
    msg.status_list[0].status = status
    with pytest.raises(ValueError, match='none of a programme'):
        programme_events_from_msg(msg)


def test_a_goal_id_of_another_length_is_refused():
    from msg_defs.conversions import programme_of_uuid

    with pytest.raises(ValueError, match='15 bytes'):
        programme_of_uuid([0] * 15)


def _legacy_status_array(stamp_ns, statuses):
    """An actionlib_msgs/GoalStatusArray as a decoder of its recorded schema gives it: only
    the field names, no actionlib_msgs package."""
    from types import SimpleNamespace as Ns

    def time(ns):
        return Ns(sec=ns // 10**9, nanosec=ns % 10**9)

    return Ns(header=Ns(stamp=time(stamp_ns), frame_id=''), status_list=[
        Ns(goal_id=Ns(stamp=time(asked_ns), id=goal_id), status=status, text=text)
        for asked_ns, goal_id, status, text in statuses])


def test_a_legacy_actionlib_report_gives_the_same_events():
    from msg_defs.conversions import programme_event_to_msg, programme_events_from_msg
    from msg_defs.programme_events import ProgrammeEvent, ProgrammeState

    # actionlib_msgs/GoalStatus: ACTIVE 1, PREEMPTED 2, SUCCEEDED 3, REJECTED 5.
    legacy = _legacy_status_array(12_360_000_000, [
        (12_345_678_901, '17', 1, 'started'), (12_345_678_901, '17', 3, 'ended'),
        (12_345_678_901, '17', 2, 'cut'), (0, '18', 5, 'refused: too late')])
    events = programme_events_from_msg(legacy)
    assert events == [
        ProgrammeEvent(ProgrammeState.STARTED, 12.345678901, 17, 12.36, 'started'),
        ProgrammeEvent(ProgrammeState.ENDED, 12.345678901, 17, 12.36, 'ended'),
        ProgrammeEvent(ProgrammeState.CUT, 12.345678901, 17, 12.36, 'cut'),
        ProgrammeEvent(ProgrammeState.REFUSED, 0.0, 18, 12.36, 'refused: too late')]
    # What the new contract carries of them is the same.
    assert [e for event in events
            for e in programme_events_from_msg(programme_event_to_msg(event))] == [
        event._replace(text='') for event in events]


@pytest.mark.parametrize('status, goal_id, match', [(0, '17', 'none of a programme'),
                                                    (1, 'abc', 'not a programme count')])
def test_a_legacy_report_that_names_no_programme_is_refused(status, goal_id, match):
    from msg_defs.conversions import programme_events_from_msg

    with pytest.raises(ValueError, match=match):
        programme_events_from_msg(_legacy_status_array(1, [(1, goal_id, status, '')]))
