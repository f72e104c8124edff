"""The player: its schedule without DDS, and a record -> play -> record round trip.

The round trip follows rosbag2_py's play tests: a known sequence is published from this
process and recorded by our ``recorder``; the ``player`` then republishes that bag while a
second recorder records it, and the two bags must hold the same messages, byte for byte,
in the same order on every topic.
"""

import itertools
import signal
import time

import pytest
import rclpy
from builtin_interfaces.msg import Duration as DurationMsg
from geometry_msgs.msg import Vector3Stamped
from nav_msgs.msg import Odometry
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, ReliabilityPolicy
from rosbags.rosbag2 import Reader
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from msg_defs.device import NS_PER_S
from msg_defs.topics import (
    ALL_TOPICS,
    BEAM_VOLTAGE,
    CLOCK,
    PULSE_PROGRAM,
    SPHERE_REFERENCE,
    SPHERE_STATE,
    SURFACE_NORMAL,
)
from sphere_twin.bag import format as bag_format
from sphere_twin.bag.reader import RecordedMessage, deserialize, read_messages
from sphere_twin.node_runtime.ros_env import DISCOVERY_RANGE_VAR
from sphere_twin.nodes.player_node import (
    CLOCK_GAP_TICK_S,
    playback_plan,
    played_line,
    progress_line,
    recorded_qos,
)
from sphere_twin.nodes.recorder_node import summary_line
from sphere_twin.processes import parameter_args, stop

T0_NS = 1_700_000_000_000_000_000


def _recorded(topic, t_ms, data=b'x'):
    return RecordedMessage(topic, 'std_msgs/msg/Empty', T0_NS + t_ms * 1_000_000,
                           T0_NS, data)


BAG = [_recorded(SURFACE_NORMAL.name, 0, b'a'), _recorded(BEAM_VOLTAGE.name, 100, b'b'),
       _recorded(SURFACE_NORMAL.name, 300, b'c'), _recorded(SURFACE_NORMAL.name, 1300, b'd')]


# --- the schedule --------------------------------------------------------------------------

def test_messages_are_due_at_their_log_time_divided_by_the_rate():
    plan = playback_plan(BAG, rate=2.0, publish_clock=False)
    assert [(i.topic, i.data) for i in plan] == [(m.topic, m.data) for m in BAG]
    assert [i.due_s for i in plan] == pytest.approx([0.0, 0.05, 0.15, 0.65])
    assert [i.due_s for i in playback_plan(BAG, rate=0.5, publish_clock=False)] == (
        pytest.approx([0.0, 0.2, 0.6, 2.6]))


def test_start_offset_skips_the_beginning_and_topics_select():
    plan = playback_plan(BAG, start_offset_s=0.1, topics={SURFACE_NORMAL.name},
                         publish_clock=False)
    # Timing is kept relative to the starting point, not to the first message played.
    assert [(i.data, i.due_s) for i in plan] == [(b'c', pytest.approx(0.2)),
                                                 (b'd', pytest.approx(1.2))]
    assert playback_plan(BAG, start_offset_s=5.0) == []
    assert playback_plan([]) == []


def test_clock_ticks_carry_the_log_times_when_the_bag_has_no_clock():
    plan = playback_plan(BAG, rate=4.0)
    messages = [i for i in plan if i.topic != CLOCK.name]
    assert [i.data for i in messages] == [m.data for m in BAG]
    ticks = [i for i in plan if i.topic == CLOCK.name]
    assert all(i.data is None for i in ticks)
    # A tick with each message's log time, just before it ...
    for message in messages:
        before = plan[plan.index(message) - 1]
        assert (before.topic, before.log_time_ns, before.due_s) == (
            CLOCK.name, message.log_time_ns, message.due_s)
    # ... and through every gap (1 s from 300 to 1300 ms) one every CLOCK_GAP_TICK_S.
    times_ms = [(i.log_time_ns - T0_NS) / 1e6 for i in ticks]
    assert times_ms == list(range(0, 1301, 100))
    assert all(b.due_s >= a.due_s for a, b in itertools.pairwise(plan))


def test_a_ten_second_gap_is_crossed_by_the_clock_and_played_on():
    gap = [_recorded(SURFACE_NORMAL.name, 0), _recorded(SURFACE_NORMAL.name, 10_000)]
    plan = playback_plan(gap, rate=10.0)
    ticks = [i for i in plan if i.topic == CLOCK.name]
    assert len(ticks) == 2 + round(10.0 / CLOCK_GAP_TICK_S) - 1
    assert max(b.due_s - a.due_s for a, b in itertools.pairwise(ticks)) == pytest.approx(
        CLOCK_GAP_TICK_S / 10.0)
    assert plan[-1].data is not None and plan[-1].due_s == pytest.approx(1.0)


def test_a_bag_with_clock_plays_its_own_clock_and_no_made_up_one():
    with_clock = [*BAG[:2], _recorded(CLOCK.name, 150, b'clock'), *BAG[2:]]
    plan = playback_plan(with_clock)
    assert [i.data for i in plan] == [m.data for m in with_clock]
    assert [i.data for i in playback_plan(with_clock, topics={BEAM_VOLTAGE.name})] == [b'b']


def test_rate_and_offset_out_of_range_are_refused():
    with pytest.raises(ValueError, match='rate must lie in'):
        playback_plan(BAG, rate=0.0)
    with pytest.raises(ValueError, match='must not be negative'):
        playback_plan(BAG, start_offset_s=-1.0)


def test_the_player_logs_its_progress_while_it_plays(context, monkeypatch):
    """A line through the node's logger at INFO every PROGRESS_PERIOD_S of wall time
    (here 0: after every publication): messages of the pass played of its total, and the bag
    time reached; the last one at the bag's end. Nothing subscribes: no graph is needed."""
    from rclpy.parameter import Parameter

    from sphere_twin.bag.locate import locate_bag
    from sphere_twin.nodes import player_node

    example = list(read_messages(locate_bag('example').directory))
    # The last 0.4 s of the example's log time (184 s: it was recorded at a fifth of real time)
    offset_s = (example[-1].log_time_ns - example[0].log_time_ns) / NS_PER_S - 0.4
    monkeypatch.setattr(player_node, 'PROGRESS_PERIOD_S', 0.0)
    node = player_node.PlayerNode(context=context, parameter_overrides=[
        Parameter('bag', value='example'), Parameter('start_offset_s', value=offset_s),
        Parameter('rate', value=4.0), Parameter('publish_clock', value=False)])
    logged = []
    monkeypatch.setattr(node, 'get_logger', lambda: type('Log', (), {'info': logged.append}))
    try:
        node.play_once()
    finally:
        node.destroy_node()
    total = len(node.plan)  # no made-up /clock: every publication is a message
    assert len(logged) == total > 10
    span_s = float(logged[-1].rsplit(' of ', 1)[1].split()[0])
    assert span_s == pytest.approx(offset_s + 0.4, abs=0.05)
    assert logged[-1] == progress_line(total, total, span_s, span_s)
    assert logged[0].startswith(f'progress: played 1 of {total} messages, bag time ')
    first_s = float(logged[0].split('bag time ')[1].split()[0])
    assert first_s == pytest.approx(offset_s, abs=0.1)


def test_a_topic_outside_the_contract_gets_the_qos_it_was_recorded_with():
    latched = bag_format.topic_metadata('/other', 'std_msgs/msg/Empty', [
        bag_format.qos_to_dict(SPHERE_REFERENCE.qos.to_profile())])
    qos = recorded_qos(latched)
    assert (qos.durability, qos.reliability, qos.depth) == (
        DurabilityPolicy.TRANSIENT_LOCAL, ReliabilityPolicy.RELIABLE, 1)
    qos = recorded_qos({'offered_qos_profiles': [
        {'reliability': 'best_effort', 'durability': 'volatile', 'depth': 0}]})
    assert (qos.reliability, qos.depth) == (ReliabilityPolicy.BEST_EFFORT, 10)
    assert recorded_qos({}).reliability == ReliabilityPolicy.RELIABLE


# --- record, play, record ------------------------------------------------------------------

READY_TIMEOUT_S = 20.0
MATCH_TIMEOUT_S = 10.0
EXIT_TIMEOUT_S = 30.0
ROUNDS = 12
ROUND_PERIOD_S = 0.02
RATE = 2.0


def _round_messages(i):
    normal = Vector3Stamped()
    normal.header.frame_id = 'world'
    normal.header.stamp.sec = i
    normal.vector.x, normal.vector.y, normal.vector.z = 0.01 * i, -0.02 * i, 1.0
    state = Odometry(child_frame_id='sphere')
    state.header.frame_id = 'world'
    state.pose.pose.orientation.w = 1.0
    state.twist.twist.angular.z = 0.5 * i
    voltage = JointState(name=['beam_1', 'beam_2', 'beam_3', 'beam_4'],
                         effort=[float(i), 0.0, 35.0, -35.0])
    programme = JointTrajectory(
        joint_names=['beam_1', 'beam_2', 'beam_3', 'beam_4'],
        points=[JointTrajectoryPoint(effort=[80.0 - i, 0.0, 0.0, 0.0],
                                     time_from_start=DurationMsg(sec=0, nanosec=0)),
                JointTrajectoryPoint(effort=[0.0] * 4,
                                     time_from_start=DurationMsg(sec=0, nanosec=500 * (i + 1)))])
    clock = Clock()
    clock.clock.sec, clock.clock.nanosec = 100 + i, 250
    return {SURFACE_NORMAL: normal, SPHERE_STATE: state, BEAM_VOLTAGE: voltage,
            PULSE_PROGRAM: programme, CLOCK: clock}


@pytest.fixture
def test_node(ros_nodes, monkeypatch):
    monkeypatch.setenv(DISCOVERY_RANGE_VAR, 'LOCALHOST')
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=ros_nodes.domain_id)
    node = Node('player_test_publisher', context=context)
    yield node
    node.destroy_node()
    rclpy.try_shutdown(context=context)


def _start_recorder(ros_nodes, bag_dir):
    recorder = ros_nodes.start('recorder', parameter_args(output_dir=str(bag_dir)))
    recorder.wait_for_output(f'recording {len(ALL_TOPICS)} topics to {bag_dir}',
                             READY_TIMEOUT_S)
    return recorder


def _stop_recorder(recorder):
    recorder.send_signal(signal.SIGINT)
    assert recorder.wait(EXIT_TIMEOUT_S) == 0
    assert stop(recorder) == 0
    return recorder.stdout_text().splitlines()[-1]


def _by_topic(bag_dir):
    """Per topic, the recorded bytes in log-time order."""
    topics = {}
    for message in read_messages(bag_dir):
        topics.setdefault(message.topic, []).append(message)
    return topics


@pytest.mark.ros
def test_playing_a_recording_while_recording_again_gives_the_same_messages(
        ros_nodes, test_node, tmp_path):
    first, second = tmp_path / 'first', tmp_path / 'second'

    # 1. A known run, recorded by our recorder.
    recorder = _start_recorder(ros_nodes, first)
    streams = list(_round_messages(0))
    publishers = {topic: test_node.create_publisher(topic.msg_type, topic.name,
                                                    topic.qos.to_profile())
                  for topic in (*streams, SPHERE_REFERENCE)}
    deadline = time.monotonic() + MATCH_TIMEOUT_S
    while any(p.get_subscription_count() < 1 for p in publishers.values()):
        assert time.monotonic() < deadline, 'the recorder never subscribed'
        time.sleep(0.05)
    # A subscription is seen a moment before it accepts messages (see the player's delay_s).
    time.sleep(0.5)
    reference = Vector3Stamped()
    reference.header.frame_id = 'world'
    reference.vector.x, reference.vector.y, reference.vector.z = 0.01, 0.02, 0.99975
    publishers[SPHERE_REFERENCE].publish(reference)
    published = {topic.name: [] for topic in publishers}
    published[SPHERE_REFERENCE.name].append(reference)
    for i in range(ROUNDS):
        for topic, msg in _round_messages(i).items():
            publishers[topic].publish(msg)
            published[topic.name].append(msg)
        time.sleep(ROUND_PERIOD_S)
    for publisher in publishers.values():
        assert publisher.wait_for_all_acked(Duration(seconds=5))
    total = 1 + len(streams) * ROUNDS
    assert _stop_recorder(recorder) == summary_line(total, len(publishers), first)
    for publisher in publishers.values():
        test_node.destroy_publisher(publisher)
    recorded = _by_topic(first)
    assert {name: [deserialize(m) for m in messages] for name, messages in recorded.items()} \
        == published

    # 2. Played back (twice as fast) while a second recorder records.
    recorder = _start_recorder(ros_nodes, second)
    player = ros_nodes.start('player', parameter_args(
        bag=str(first), rate=RATE, wait_for_subscribers_s=MATCH_TIMEOUT_S, delay_s=0.5))
    assert player.wait(EXIT_TIMEOUT_S) == 0
    assert stop(player) == 0
    assert player.stdout_text().splitlines()[-1] == played_line(total)
    assert 'without subscribers' not in player.stderr_text()
    assert _stop_recorder(recorder) == summary_line(total, len(publishers), second)

    # 3. The same messages: contents (the very bytes) and order, topic by topic.
    replayed = _by_topic(second)
    assert set(replayed) == set(recorded)
    for name, messages in recorded.items():
        assert [m.data for m in replayed[name]] == [m.data for m in messages], name
        assert [m.type_name for m in replayed[name]] == [m.type_name for m in messages]
    # Played at twice the speed: never faster than that (the first message may be late).
    span = {bag: (max(m.log_time_ns for ms in topics.values() for m in ms)
                  - min(m.log_time_ns for ms in topics.values() for m in ms)) / NS_PER_S
            for bag, topics in (('first', recorded), ('second', replayed))}
    assert span['second'] < span['first']
    # The independent reader agrees, and the latched reference was offered latched again.
    with Reader(second) as reader:
        assert reader.message_count == total
        (reference_connection,) = [c for c in reader.connections
                                   if c.topic == SPHERE_REFERENCE.name]
        assert reference_connection.ext.offered_qos_profiles[0].durability.name == (
            'TRANSIENT_LOCAL')
