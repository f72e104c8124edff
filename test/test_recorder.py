"""The recorder: bag layout as rosbag2 writes it, and a real recording read back independently.

The layout tests need no DDS. The last test starts the ``recorder`` executable on a domain
of its own, publishes known messages from this process (one of them latched before the
recorder starts), stops it with SIGINT to its PID and reads the bag with ``rosbags`` (which
shares no code with the writer) and with the ``mcap`` reader and its ROS 2 decoder.
"""

import datetime
import signal
import time

import pytest
import rclpy
import yaml
from builtin_interfaces.msg import Duration as DurationMsg
from geometry_msgs.msg import Vector3Stamped
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from nav_msgs.msg import Odometry
from rclpy.duration import Duration, Infinite
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import (
    DurabilityPolicy,
    HistoryPolicy,
    LivelinessPolicy,
    QoSProfile,
    ReliabilityPolicy,
)
from rclpy.serialization import deserialize_message, serialize_message
from rosbags.interfaces import QosDurability, QosHistory, QosReliability
from rosbags.rosbag2 import Reader
from rosbags.rosbag2.metadata import parse_qos
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from msg_defs.topics import (
    ALL_TOPICS,
    BEAM_VOLTAGE,
    LATCHED_QOS,
    PULSE_PROGRAM,
    SPHERE_REFERENCE,
    SPHERE_STATE,
    SURFACE_NORMAL,
)
from sphere_twin.bag import format as bag_format
from sphere_twin.bag.reader import deserialize, read_messages, read_metadata
from sphere_twin.bag.writer import BagWriter
from sphere_twin.node_runtime.parameter_specs import StartupError
from sphere_twin.node_runtime.ros_env import DISCOVERY_RANGE_VAR, startup_error_line
from sphere_twin.nodes.recorder_node import (
    RecorderNode,
    StopRequest,
    default_output_dir,
    open_bag,
    summary_line,
)
from sphere_twin.processes import parameter_args, stop

JAZZY = get_typestore(Stores.ROS2_JAZZY)
DELIMITER = '=' * 80
INFINITE_TIME = {'sec': 9223372036, 'nsec': 854775807}
# What the ROS graph reports for a publisher (get_publishers_info_by_topic): history and
# depth are not announced, unset durations are infinite.
DISCOVERED_PUBLISHER_QOS = QoSProfile(
    history=HistoryPolicy.UNKNOWN, depth=0, reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL, deadline=Infinite, lifespan=Infinite,
    liveliness=LivelinessPolicy.AUTOMATIC, liveliness_lease_duration=Infinite)


def _msg_file_text(type_name):
    return bag_format.find_msg_file(type_name).read_text()


# --- message definitions -------------------------------------------------------------------

def test_odometry_definition_is_rosbag2s_full_text_with_every_dependency_once():
    definition = bag_format.message_definition('nav_msgs/msg/Odometry')

    assert definition.startswith(_msg_file_text('nav_msgs/msg/Odometry'))
    # As rosbag2_cpp writes it: dependencies named as the fields name them, depth first,
    # each type's own dependencies in sorted order, every type once.
    assert [line for line in definition.splitlines() if line.startswith('MSG: ')] == [
        'MSG: geometry_msgs/PoseWithCovariance',
        'MSG: geometry_msgs/Pose',
        'MSG: geometry_msgs/Point',
        'MSG: geometry_msgs/Quaternion',
        'MSG: geometry_msgs/TwistWithCovariance',
        'MSG: geometry_msgs/Twist',
        'MSG: geometry_msgs/Vector3',
        'MSG: std_msgs/Header',
        'MSG: builtin_interfaces/Time',
    ]
    header_section = (f'\n{DELIMITER}\nMSG: std_msgs/Header\n'
                      + _msg_file_text('std_msgs/msg/Header'))
    assert header_section in definition
    assert f'\n{DELIMITER}\nMSG: geometry_msgs/PoseWithCovariance\n' in definition
    assert definition.count(DELIMITER) == 9


def test_dependencies_are_found_as_rosbag2_finds_them():
    text = ('# a comment naming std_msgs/Header\n'
            'std_msgs/Header header\n'
            'Pose[] poses\n'
            'float64[36] covariance\n'
            'uint8 MODE=1\n'
            'string<=8 label\n')
    assert bag_format.msg_dependencies(text, 'geometry_msgs') == [
        'geometry_msgs/Pose', 'std_msgs/Header']


@pytest.mark.parametrize('topic', ALL_TOPICS, ids=lambda t: t.name)
def test_every_contract_definition_parses_to_jazzys_types(topic):
    type_name = bag_format.type_name_of(topic.msg_type)
    parsed = get_types_from_msg(bag_format.message_definition(type_name), type_name)

    assert type_name in parsed
    for name, fields in parsed.items():
        assert fields == JAZZY.fielddefs[name], name


def test_a_missing_definition_is_a_clear_error_naming_where_it_looked():
    with pytest.raises(bag_format.MessageDefinitionNotFoundError,
                       match=r'no \.msg definition of no_such_msgs/msg/Thing; looked in: .*'
                             r'no_such_msgs/msg/Thing\.msg'):
        bag_format.message_definition('no_such_msgs/msg/Thing')
    with pytest.raises(ValueError, match='not a message type name'):
        bag_format.find_msg_file('Odometry')


def test_definitions_come_from_the_share_dir_next_to_the_python_prefix(monkeypatch):
    monkeypatch.delenv('AMENT_PREFIX_PATH', raising=False)
    path = bag_format.find_msg_file('nav_msgs/msg/Odometry')
    assert path.parts[-4:] == ('share', 'nav_msgs', 'msg', 'Odometry.msg')


def test_the_ament_index_comes_first_when_a_ros_installation_is_sourced(tmp_path, monkeypatch):
    prefix = tmp_path / 'ros'
    (prefix / 'share' / 'ament_index' / 'resource_index' / 'packages').mkdir(parents=True)
    (prefix / 'share' / 'ament_index' / 'resource_index' / 'packages' / 'nav_msgs').touch()
    msg_dir = prefix / 'share' / 'nav_msgs' / 'msg'
    msg_dir.mkdir(parents=True)
    (msg_dir / 'Odometry.msg').write_text('float64 x\n')
    monkeypatch.setenv('AMENT_PREFIX_PATH', str(prefix))

    assert bag_format.find_msg_file('nav_msgs/msg/Odometry') == msg_dir / 'Odometry.msg'


# --- QoS -----------------------------------------------------------------------------------

def test_qos_is_recorded_with_rosbag2s_v9_policy_names():
    assert bag_format.qos_to_dict(LATCHED_QOS.to_profile()) == {
        'history': 'keep_last', 'depth': 1, 'reliability': 'reliable',
        'durability': 'transient_local', 'deadline': {'sec': 0, 'nsec': 0},
        'lifespan': {'sec': 0, 'nsec': 0}, 'liveliness': 'system_default',
        'liveliness_lease_duration': {'sec': 0, 'nsec': 0},
        'avoid_ros_namespace_conventions': False}
    discovered = bag_format.qos_to_dict(DISCOVERED_PUBLISHER_QOS)
    assert discovered['history'] == 'unknown'
    assert discovered['deadline'] == discovered['lifespan'] == INFINITE_TIME
    assert discovered['liveliness'] == 'automatic'
    assert list(discovered) == list(bag_format.QOS_KEYS)
    assert bag_format.qos_to_dict(QoSProfile(
        depth=5, deadline=Duration(seconds=1, nanoseconds=5)))['deadline'] == {
        'sec': 1, 'nsec': 5}


@pytest.mark.parametrize('profile', [
    *(topic.qos.to_profile() for topic in ALL_TOPICS), DISCOVERED_PUBLISHER_QOS])
def test_channel_and_metadata_qos_are_the_same_qos_for_rosbags(profile):
    dicts = [bag_format.qos_to_dict(profile)]
    channel_text = bag_format.channel_metadata(dicts)['offered_qos_profiles']
    in_metadata = bag_format.topic_metadata('/t', 'std_msgs/msg/Empty', dicts)

    from_channel = parse_qos(channel_text)
    assert from_channel == parse_qos(in_metadata['offered_qos_profiles'])
    assert bag_format.parse_offered_qos_yaml(channel_text) == dicts
    (qos,) = from_channel
    assert qos.reliability == (QosReliability.RELIABLE
                               if profile.reliability == ReliabilityPolicy.RELIABLE
                               else QosReliability.BEST_EFFORT)
    assert qos.depth == profile.depth


# --- the writer ----------------------------------------------------------------------------

def _vector3(i, frame='world'):
    msg = Vector3Stamped()
    msg.header.frame_id = frame
    msg.header.stamp.sec = i
    msg.vector.x, msg.vector.y, msg.vector.z = float(i), -0.5 * i, 1.0
    return msg


def _odometry(i):
    msg = Odometry(child_frame_id='sphere')
    msg.header.frame_id = 'world'
    msg.pose.pose.orientation.w = 1.0
    msg.pose.pose.position.z = 1e-3 * i
    msg.twist.twist.angular.x = 0.25 * i
    msg.pose.covariance[7] = float(i)
    return msg


def _voltages(i):
    return JointState(name=['beam_1', 'beam_2', 'beam_3', 'beam_4'],
                      effort=[float(i), 2.0 * i, 0.0, 80.0])


def _programme(i):
    return JointTrajectory(
        joint_names=['beam_1', 'beam_2', 'beam_3', 'beam_4'],
        points=[JointTrajectoryPoint(effort=[35.0, 35.0, 80.0 - i, 0.0],
                                     time_from_start=DurationMsg(sec=0, nanosec=0)),
                JointTrajectoryPoint(effort=[0.0] * 4,
                                     time_from_start=DurationMsg(sec=0, nanosec=1000 * (i + 1)))])


def _write_small_bag(path):
    """Three topics, interleaved; returns the written (topic, log_time, bytes) in order."""
    qos = {SURFACE_NORMAL.name: [bag_format.qos_to_dict(SURFACE_NORMAL.qos.to_profile())],
           SPHERE_REFERENCE.name: [bag_format.qos_to_dict(DISCOVERED_PUBLISHER_QOS)],
           SPHERE_STATE.name: [bag_format.qos_to_dict(SPHERE_STATE.qos.to_profile())] * 2}
    written = []
    with BagWriter(path) as bag:
        for topic in (SURFACE_NORMAL, SPHERE_REFERENCE, SPHERE_STATE):
            bag.add_topic(topic.name, bag_format.type_name_of(topic.msg_type), qos[topic.name],
                          'RIHS01_' + '0' * 64)
        t0 = 1_700_000_000_000_000_000
        for i in range(6):
            for k, (topic, make) in enumerate(((SURFACE_NORMAL, _vector3),
                                               (SPHERE_STATE, _odometry))):
                log_time = t0 + 10_000_000 * i + k
                data = serialize_message(make(i))
                bag.write(topic.name, data, log_time, log_time - 1000)
                written.append((topic.name, log_time, data))
        data = serialize_message(_vector3(99))
        bag.write(SPHERE_REFERENCE.name, data, t0 + 60_000_000)
        written.append((SPHERE_REFERENCE.name, t0 + 60_000_000, data))
    return written, qos


def test_a_new_bag_is_recognisably_a_bag_before_its_first_message(tmp_path):
    bag = BagWriter(tmp_path / 'fresh')
    metadata = read_metadata(tmp_path / 'fresh')
    assert (metadata['version'], metadata['message_count']) == (9, 0)
    assert metadata['topics_with_message_count'] == []
    assert metadata['relative_file_paths'] == ['fresh_0.mcap']

    bag.add_topic(SURFACE_NORMAL.name, 'geometry_msgs/msg/Vector3Stamped',
                  [bag_format.qos_to_dict(SURFACE_NORMAL.qos.to_profile())])
    # A recorder killed now still leaves the topic listed.
    (topic,) = read_metadata(tmp_path / 'fresh')['topics_with_message_count']
    assert (topic['topic_metadata']['name'], topic['message_count']) == (
        SURFACE_NORMAL.name, 0)
    bag.close()
    with Reader(tmp_path / 'fresh') as reader:
        assert reader.message_count == 0
        assert [c.topic for c in reader.connections] == [SURFACE_NORMAL.name]


def test_written_bag_metadata_is_rosbag2_version_9(tmp_path):
    written, qos = _write_small_bag(tmp_path / 'small')
    text = (tmp_path / 'small' / 'metadata.yaml').read_text()
    metadata = yaml.safe_load(text)['rosbag2_bagfile_information']

    assert list(metadata) == list(bag_format.BAG_METADATA_KEYS)
    assert metadata['version'] == 9
    assert metadata['storage_identifier'] == 'mcap'
    assert metadata['relative_file_paths'] == ['small_0.mcap']
    assert (metadata['compression_format'], metadata['compression_mode']) == ('', '')
    assert 'compression_format: ""' in text and 'custom_data: ~' in text
    assert metadata['ros_distro'] == 'jazzy'
    log_times = [t for _, t, _ in written]
    assert metadata['message_count'] == len(written) == 13
    assert metadata['starting_time']['nanoseconds_since_epoch'] == min(log_times)
    assert metadata['duration']['nanoseconds'] == max(log_times) - min(log_times)
    (file_info,) = metadata['files']
    assert file_info == {'path': 'small_0.mcap', 'starting_time': metadata['starting_time'],
                         'duration': metadata['duration'], 'message_count': 13}
    topics = {t['topic_metadata']['name']: t for t in metadata['topics_with_message_count']}
    assert {name: t['message_count'] for name, t in topics.items()} == {
        SURFACE_NORMAL.name: 6, SPHERE_REFERENCE.name: 1, SPHERE_STATE.name: 6}
    state = topics[SPHERE_STATE.name]['topic_metadata']
    assert list(state) == ['name', 'type', 'serialization_format', 'offered_qos_profiles',
                           'type_description_hash']
    assert state['type'] == 'nav_msgs/msg/Odometry'
    assert state['serialization_format'] == 'cdr'
    assert state['offered_qos_profiles'] == qos[SPHERE_STATE.name]
    assert state['type_description_hash'] == 'RIHS01_' + '0' * 64


def test_written_bag_reads_back_identically_with_rosbags(tmp_path):
    written, _ = _write_small_bag(tmp_path / 'small')

    with Reader(tmp_path / 'small') as reader:
        assert reader.message_count == 13
        by_topic = {c.topic: c for c in reader.connections}
        assert by_topic[SPHERE_REFERENCE.name].ext.offered_qos_profiles[0].durability == (
            QosDurability.TRANSIENT_LOCAL)
        assert by_topic[SPHERE_REFERENCE.name].ext.offered_qos_profiles[0].history == (
            QosHistory.UNKNOWN)
        read = [(c.topic, t, bytes(d)) for c, t, d in reader.messages()]
        state = [JAZZY.deserialize_cdr(d, c.msgtype) for c, _, d in reader.messages()
                 if c.topic == SPHERE_STATE.name]
    assert read == written
    assert [m.twist.twist.angular.x for m in state] == [0.25 * i for i in range(6)]
    assert [m.pose.covariance[7] for m in state] == [float(i) for i in range(6)]
    assert {m.child_frame_id for m in state} == {'sphere'}


def test_written_bag_is_an_mcap_file_with_ros2_schemas_and_zstd_chunks(tmp_path):
    written, qos = _write_small_bag(tmp_path / 'small')

    with open(tmp_path / 'small' / 'small_0.mcap', 'rb') as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        assert reader.get_header().profile == 'ros2'
        summary = reader.get_summary()
        assert {c.compression for c in summary.chunk_indexes} == {'zstd'}
        assert {s.name: (s.encoding, s.data.decode()) for s in summary.schemas.values()} == {
            name: ('ros2msg', bag_format.message_definition(name))
            for name in ('geometry_msgs/msg/Vector3Stamped', 'nav_msgs/msg/Odometry')}
        for channel in summary.channels.values():
            assert channel.message_encoding == 'cdr'
            assert channel.metadata == {
                'offered_qos_profiles': bag_format.offered_qos_yaml(qos[channel.topic]),
                'topic_type_hash': 'RIHS01_' + '0' * 64}
        (record,) = [m for m in reader.iter_metadata() if m.name == 'rosbag2']
        decoded = [(c.topic, m.log_time, m.publish_time, d)
                   for _, c, m, d in reader.iter_decoded_messages(log_time_order=True)]
    assert yaml.safe_load(record.metadata['serialized_metadata']) == read_metadata(
        tmp_path / 'small')
    assert [(topic, t) for topic, t, _, _ in decoded] == [(topic, t) for topic, t, _ in written]
    assert decoded[0][2] == written[0][1] - 1000
    assert [d.vector.x for topic, _, _, d in decoded if topic == SURFACE_NORMAL.name] == [
        float(i) for i in range(6)]


def test_our_reader_returns_the_messages_in_order(tmp_path):
    written, _ = _write_small_bag(tmp_path / 'small')
    read = list(read_messages(tmp_path / 'small'))
    assert [(m.topic, m.log_time_ns, m.data) for m in read] == written
    assert deserialize(read[-1]) == _vector3(99)
    assert [m.topic for m in read_messages(tmp_path / 'small', [SPHERE_REFERENCE.name])] == [
        SPHERE_REFERENCE.name]


def test_rosbags_silently_drops_a_topic_whose_two_qos_descriptions_differ(tmp_path):
    # Why channel and metadata QoS come from one function: the hazard this guards against.
    _write_small_bag(tmp_path / 'small')
    path = tmp_path / 'small' / 'metadata.yaml'
    document = yaml.safe_load(path.read_text())
    for topic in document['rosbag2_bagfile_information']['topics_with_message_count']:
        if topic['topic_metadata']['name'] == SURFACE_NORMAL.name:
            topic['topic_metadata']['offered_qos_profiles'][0]['depth'] = 11
    path.write_text(yaml.safe_dump(document, sort_keys=False))
    with Reader(tmp_path / 'small') as reader:
        topics = [c.topic for c, _, _ in reader.messages()]
    assert SURFACE_NORMAL.name not in topics
    assert topics.count(SPHERE_STATE.name) == 6


def test_writer_refuses_a_non_empty_directory_and_unknown_compression(tmp_path):
    (tmp_path / 'used').mkdir()
    (tmp_path / 'used' / 'x').touch()
    with pytest.raises(FileExistsError, match='not empty'):
        BagWriter(tmp_path / 'used')
    with pytest.raises(ValueError, match='unknown compression'):
        BagWriter(tmp_path / 'new', compression='bz2')
    assert not (tmp_path / 'new').exists()


def test_stop_request_turns_the_first_signal_into_a_flag():
    stop_request = StopRequest()
    assert not stop_request.requested
    stop_request.request(signal.SIGTERM)
    stop_request.request(signal.SIGINT)
    assert stop_request.requested
    assert stop_request.signal_name == 'SIGTERM'


# --- a real recording ----------------------------------------------------------------------

READY_TIMEOUT_S = 20.0
MATCH_TIMEOUT_S = 10.0
ACK_TIMEOUT = Duration(seconds=5)
EXIT_TIMEOUT_S = 10.0
MESSAGES_PER_TOPIC = 8


@pytest.fixture
def publisher_node(ros_nodes, monkeypatch):
    """A node of this process on the recorder's domain."""
    monkeypatch.setenv(DISCOVERY_RANGE_VAR, 'LOCALHOST')
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=ros_nodes.domain_id)
    node = Node('recorder_test_publisher', context=context)
    yield node
    node.destroy_node()
    rclpy.try_shutdown(context=context)


def _wait_for_subscriber(publisher):
    deadline = time.monotonic() + MATCH_TIMEOUT_S
    while publisher.get_subscription_count() < 1:
        assert time.monotonic() < deadline, f'recorder never subscribed to {publisher.topic}'
        time.sleep(0.05)


@pytest.mark.ros
def test_recorder_records_what_was_published_and_rosbags_reads_it_back(
        ros_nodes, publisher_node, tmp_path):
    bag_dir = tmp_path / 'run'
    streams = {SURFACE_NORMAL: _vector3, SPHERE_STATE: _odometry, BEAM_VOLTAGE: _voltages,
               PULSE_PROGRAM: _programme}
    publishers = {topic: publisher_node.create_publisher(topic.msg_type, topic.name,
                                                         topic.qos.to_profile())
                  for topic in (*streams, SPHERE_REFERENCE)}
    # Latched before the recorder exists: it must still be recorded.
    reference = _vector3(42)
    publishers[SPHERE_REFERENCE].publish(reference)

    recorder = ros_nodes.start('recorder', parameter_args(output_dir=str(bag_dir)))
    recorder.wait_for_output(f'recording {len(ALL_TOPICS)} topics to {bag_dir}',
                             READY_TIMEOUT_S)
    for publisher in publishers.values():
        _wait_for_subscriber(publisher)
    published = {topic.name: [] for topic in publishers}
    published[SPHERE_REFERENCE.name].append(reference)
    for i in range(MESSAGES_PER_TOPIC):
        for topic, make in streams.items():
            msg = make(i)
            publishers[topic].publish(msg)
            published[topic.name].append(msg)
    # No more messages per topic than the contract's history depth, so none is overwritten
    # before it is acknowledged; acknowledged means delivered to the recorder.
    assert all(topic.qos.depth >= MESSAGES_PER_TOPIC for topic in streams)
    for publisher in publishers.values():
        assert publisher.wait_for_all_acked(ACK_TIMEOUT)

    recorder.send_signal(signal.SIGINT)
    assert recorder.wait(EXIT_TIMEOUT_S) == 0
    assert stop(recorder) == 0
    total = 1 + len(streams) * MESSAGES_PER_TOPIC
    assert recorder.stdout_text().splitlines()[-1] == summary_line(total, 5, bag_dir)
    assert 'Traceback' not in recorder.stderr_text()

    # rosbags, independently of our writer: every message, in order, same content.
    with Reader(bag_dir) as reader:
        assert reader.message_count == total
        by_topic = {c.topic: c for c in reader.connections}
        assert set(by_topic) == set(published)
        for connection in by_topic.values():
            assert connection.digest.startswith('RIHS01_')
        assert by_topic[SPHERE_REFERENCE.name].ext.offered_qos_profiles[0].durability == (
            QosDurability.TRANSIENT_LOCAL)
        recorded = {name: [] for name in published}
        log_times = []
        for connection, log_time, data in reader.messages():
            recorded[connection.topic].append((bytes(data), JAZZY.deserialize_cdr(
                data, connection.msgtype)))
            log_times.append(log_time)
    assert log_times == sorted(log_times)
    # Compared as messages: the CDR padding bytes on the wire are unspecified.
    for name, messages in published.items():
        msg_type = type(messages[0])
        assert [deserialize_message(data, msg_type) for data, _ in recorded[name]] == (
            messages), name
    assert [m.vector.x for _, m in recorded[SURFACE_NORMAL.name]] == [
        float(i) for i in range(MESSAGES_PER_TOPIC)]
    assert [m.pose.pose.position.z for _, m in recorded[SPHERE_STATE.name]] == [
        1e-3 * i for i in range(MESSAGES_PER_TOPIC)]
    assert [list(m.effort) for _, m in recorded[BEAM_VOLTAGE.name]] == [
        [float(i), 2.0 * i, 0.0, 80.0] for i in range(MESSAGES_PER_TOPIC)]
    assert [m.points[1].time_from_start.nanosec for _, m in recorded[PULSE_PROGRAM.name]] == [
        1000 * (i + 1) for i in range(MESSAGES_PER_TOPIC)]
    ((_, latched),) = recorded[SPHERE_REFERENCE.name]
    assert (latched.vector.x, latched.header.frame_id) == (42.0, 'world')

    # The mcap reader and its ROS 2 decoder, from the schemas in the file.
    with open(bag_dir / 'run_0.mcap', 'rb') as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        decoded = [(c.topic, d) for _, c, _, d in reader.iter_decoded_messages()]
    assert len(decoded) == total
    assert [d.effort[3] for topic, d in decoded if topic == BEAM_VOLTAGE.name] == [
        80.0] * MESSAGES_PER_TOPIC
    assert [d.child_frame_id for topic, d in decoded if topic == SPHERE_STATE.name] == [
        'sphere'] * MESSAGES_PER_TOPIC


@pytest.mark.ros
def test_recorder_stopped_by_sigterm_leaves_an_empty_bag_rosbags_opens(ros_nodes, tmp_path):
    bag_dir = tmp_path / 'quiet'
    recorder = ros_nodes.start('recorder', parameter_args(output_dir=str(bag_dir)))
    recorder.wait_for_output(f'to {bag_dir}', READY_TIMEOUT_S)
    recorder.send_signal(signal.SIGTERM)
    assert recorder.wait(EXIT_TIMEOUT_S) == 0
    assert stop(recorder) == 0
    assert recorder.stdout_text().splitlines()[-1] == summary_line(0, 0, bag_dir)
    with Reader(bag_dir) as reader:
        assert reader.message_count == 0
        assert reader.connections == []


@pytest.mark.ros
def test_recorder_node_records_the_chosen_topics_with_the_contract_qos_when_alone(
        context, tmp_path):
    node = RecorderNode(context=context, parameter_overrides=[
        Parameter('output_dir', value=str(tmp_path / 'one')),
        Parameter('topics', value=[SPHERE_REFERENCE.name])])
    try:
        assert node.topics == (SPHERE_REFERENCE,)
        assert node.describe_parameter('topics').read_only
        data = serialize_message(_vector3(3))
        node.on_message(SPHERE_REFERENCE, data, {'source_timestamp': 123})
        node.on_message(SPHERE_REFERENCE, data, {'source_timestamp': 456})
        assert node.finish() == summary_line(2, 1, tmp_path / 'one')
    finally:
        node.destroy_node()
    # No publisher left in the graph: the contract's profile and our subscription's hash.
    (topic,) = read_metadata(tmp_path / 'one')['topics_with_message_count']
    assert topic['message_count'] == 2
    assert topic['topic_metadata']['offered_qos_profiles'] == [
        bag_format.qos_to_dict(LATCHED_QOS.to_profile())]
    assert topic['topic_metadata']['type_description_hash'].startswith('RIHS01_')
    assert [m.publish_time_ns for m in read_messages(tmp_path / 'one')] == [123, 456]


@pytest.mark.ros
def test_recorder_node_rejects_a_topic_outside_the_contract(context, tmp_path):
    with pytest.raises(ValueError, match="no topic '/nope' in the contract"):
        RecorderNode(context=context, parameter_overrides=[
            Parameter('output_dir', value=str(tmp_path / 'x')),
            Parameter('topics', value=['/nope'])])
    assert not (tmp_path / 'x').exists()


def test_an_output_dir_that_cannot_be_made_is_named_with_the_reason_in_words(tmp_path):
    """The recorder's one line says the path and why, not an OSError's number (it said
    `recorder: error: 20`), and leaves nothing behind."""
    (tmp_path / 'notes.txt').write_text('a file')
    cases = {
        tmp_path / 'notes.txt' / 'bag': f'cannot create output_dir {tmp_path}/notes.txt/bag: '
                                        'Not a directory',
        tmp_path / 'notes.txt': f'parameter output_dir: bag directory {tmp_path}/notes.txt is '
                                'a file, not a directory: give a new or empty directory',
    }
    for output_dir, says in cases.items():
        with pytest.raises(StartupError) as raised:
            open_bag(str(output_dir), 'zstd', 1 << 20)
        assert startup_error_line('recorder', raised.value).startswith(
            f'recorder: error: {says}')
    assert [p.name for p in tmp_path.iterdir()] == ['notes.txt']
    assert (tmp_path / 'notes.txt').read_text() == 'a file'


def test_an_os_error_at_start_up_is_said_in_words():
    """Whatever OSError a node's start-up lets through, its line names the file and the
    reason, not the error's number (its first argument)."""
    error = NotADirectoryError(20, 'Not a directory', '/etc/hostname/bag')
    assert startup_error_line('player', error) == (
        'player: error: /etc/hostname/bag: Not a directory')
    assert startup_error_line('player', PermissionError(13, 'Permission denied')) == (
        'player: error: Permission denied')


def test_default_bag_directory_is_named_by_utc_time():
    now = datetime.datetime(2025, 1, 2, 3, 4, 5, tzinfo=datetime.UTC)
    assert default_output_dir(now) == 'bags/run_20250102T030405Z'
