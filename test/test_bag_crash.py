"""Crash safety of bags: what survives a recorder that is killed, and `sphere-twin bag repair`.

The file-level tests cut and damage bags written by :class:`BagWriter` and need no DDS. The
last test kills the real ``recorder`` process with SIGKILL while messages are streaming and
counts what was lost; ``rosbags`` (which shares no code with ours) then reads the repaired bag.
"""

import signal
import time

import pytest
import rclpy
import yaml
from geometry_msgs.msg import Vector3Stamped
from mcap.reader import make_reader
from mcap.writer import Writer
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.serialization import deserialize_message, serialize_message
from rosbags.rosbag2 import Reader
from rosbags.typesys import Stores, get_typestore
from sensor_msgs.msg import JointState

from msg_defs.topics import BEAM_VOLTAGE, SURFACE_NORMAL
from sphere_twin import cli
from sphere_twin.bag import format as bag_format
from sphere_twin.bag.reader import (
    BagError,
    has_footer,
    read_messages,
    read_metadata,
    scan_mcap,
)
from sphere_twin.bag.repair import repair_bag
from sphere_twin.bag.writer import BagWriter
from sphere_twin.node_runtime.ros_env import DISCOVERY_RANGE_VAR
from sphere_twin.processes import parameter_args, stop

JAZZY = get_typestore(Stores.ROS2_JAZZY)
T0_NS = 1_700_000_000_000_000_000
MESSAGES_PER_CHUNK = 10
CHUNKS = 3
CUT_STRIDE_BYTES = 23


def _normal(i):
    msg = Vector3Stamped()
    msg.header.frame_id = 'world'
    msg.header.stamp.sec = i
    msg.vector.x, msg.vector.y, msg.vector.z = float(i), 0.0, 1.0
    return msg


def _voltage(i):
    return JointState(name=['beam_1', 'beam_2', 'beam_3', 'beam_4'],
                      effort=[float(i), 0.0, 0.0, 0.0])


def _add_topics(bag):
    for topic in (SURFACE_NORMAL, BEAM_VOLTAGE):
        bag.add_contract_topic(topic)


def _write_flushed_bag(path):
    """A bag as a recorder killed after CHUNKS flushed chunks leaves it.

    Returns
    -------
    bytes
        The MCAP file, without summary and footer.
    list of int
        The offset at which each chunk record ends, from the chunk index the file gets when
        it is closed (closing only appends to the bytes returned).
    """
    bag = BagWriter(path)
    _add_topics(bag)
    for i in range(MESSAGES_PER_CHUNK * CHUNKS):
        topic, make = (SURFACE_NORMAL, _normal) if i % 2 == 0 else (BEAM_VOLTAGE, _voltage)
        bag.write(topic.name, serialize_message(make(i)), T0_NS + i * 1_000_000)
        if (i + 1) % MESSAGES_PER_CHUNK == 0:
            bag.flush()
    mcap_path = path / bag.file_name
    open_bytes = mcap_path.read_bytes()
    open_metadata = (path / 'metadata.yaml').read_text()
    bag.close()
    with open(mcap_path, 'rb') as stream:
        chunk_indexes = make_reader(stream).get_summary().chunk_indexes
    assert mcap_path.read_bytes().startswith(open_bytes)
    mcap_path.write_bytes(open_bytes)
    (path / 'metadata.yaml').write_text(open_metadata)
    return open_bytes, [c.chunk_start_offset + c.chunk_length for c in chunk_indexes]


def _indices(path):
    """Index i of every readable message (stamp.sec of normals, effort[0] of voltages)."""
    indices = []
    for message in read_messages(path):
        if message.topic == SURFACE_NORMAL.name:
            indices.append(deserialize_message(message.data, Vector3Stamped).header.stamp.sec)
        else:
            indices.append(int(deserialize_message(message.data, JointState).effort[0]))
    return indices


# --- a bag cut anywhere --------------------------------------------------------------------

def test_a_bag_cut_at_any_byte_yields_exactly_its_completed_chunks(tmp_path):
    data, chunk_ends = _write_flushed_bag(tmp_path / 'cut')
    mcap_path = tmp_path / 'cut' / 'cut_0.mcap'
    assert not has_footer(mcap_path)
    # Lengths from the end of the magic and header record to the end of the file: a
    # stride through every record, and each side of every chunk's end.
    header_end = 8 + 9 + int.from_bytes(data[9:17], 'little')
    lengths = {*range(header_end, len(data) + 1, CUT_STRIDE_BYTES), len(data),
               *(end + d for end in chunk_ends for d in (-1, 0, 1))}
    assert len(lengths) > 50
    for length in sorted(lengths):
        mcap_path.write_bytes(data[:length])
        complete_chunks = sum(end <= length for end in chunk_ends)
        assert _indices(tmp_path / 'cut') == list(range(MESSAGES_PER_CHUNK * complete_chunks)), (
            length)


def test_a_damaged_chunk_ends_reading_with_the_chunks_before_it(tmp_path):
    data, chunk_ends = _write_flushed_bag(tmp_path / 'bad')
    # Overwrite the middle of the last chunk, as a torn disk write would.
    middle = (chunk_ends[1] + chunk_ends[2]) // 2
    damaged = data[:middle] + b'\x00' * 16 + data[middle + 16:]
    (tmp_path / 'bad' / 'bad_0.mcap').write_bytes(damaged)

    scan = scan_mcap(tmp_path / 'bad' / 'bad_0.mcap')
    assert not scan.complete
    assert scan.chunk_count == 2
    assert 'damaged chunk' in scan.stop_reason
    assert _indices(tmp_path / 'bad') == list(range(2 * MESSAGES_PER_CHUNK))


def test_repair_rebuilds_summary_and_metadata_that_rosbags_reads(tmp_path, capsys):
    data, chunk_ends = _write_flushed_bag(tmp_path / 'killed')
    bag_dir = tmp_path / 'killed'
    # Killed while a third chunk was half written.
    cut = (chunk_ends[1] + chunk_ends[2]) // 2
    (bag_dir / 'killed_0.mcap').write_bytes(data[:cut])
    assert read_metadata(bag_dir)['message_count'] == 0
    expected = _indices(bag_dir)
    assert expected == list(range(2 * MESSAGES_PER_CHUNK))

    assert cli.main(['bag', 'repair', str(bag_dir)]) == 0
    line = capsys.readouterr().out.strip()
    assert line.startswith(f'repaired {bag_dir}: 20 messages on 2 topics recovered from 2 '
                           'complete chunks (metadata.yaml listed 0; the file ends inside a '
                           'record at byte')
    assert line.endswith('damaged file kept as killed_0.mcap.bak')
    assert (bag_dir / 'killed_0.mcap.bak').read_bytes() == data[:cut]
    assert has_footer(bag_dir / 'killed_0.mcap')

    metadata = read_metadata(bag_dir)
    assert metadata['message_count'] == 20
    assert {t['topic_metadata']['name']: t['message_count']
            for t in metadata['topics_with_message_count']} == {
        SURFACE_NORMAL.name: 10, BEAM_VOLTAGE.name: 10}
    assert metadata['starting_time']['nanoseconds_since_epoch'] == T0_NS
    assert metadata['duration']['nanoseconds'] == 19 * 1_000_000
    assert metadata['topics_with_message_count'][0]['topic_metadata'][
        'offered_qos_profiles'] == [bag_format.qos_to_dict(SURFACE_NORMAL.qos.to_profile())]

    with Reader(bag_dir) as reader:
        assert reader.message_count == 20
        read = [(c.topic, t, bytes(d), c.msgtype) for c, t, d in reader.messages()]
    assert [t for _, t, _, _ in read] == [T0_NS + i * 1_000_000 for i in range(20)]
    assert [JAZZY.deserialize_cdr(d, msgtype).vector.x for topic, _, d, msgtype in read
            if topic == SURFACE_NORMAL.name] == [float(i) for i in range(0, 20, 2)]
    assert [deserialize_message(d, JointState).effort[0] for topic, _, d, _ in read
            if topic == BEAM_VOLTAGE.name] == [float(i) for i in range(1, 20, 2)]
    assert _indices(bag_dir) == expected

    # A second repair finds nothing to do.
    assert cli.main(['bag', 'repair', str(bag_dir)]) == 0
    assert capsys.readouterr().out.strip() == (
        f'{bag_dir}: intact, 20 messages on 2 topics; nothing to repair')


def test_repair_of_a_closed_bag_with_stale_metadata_rewrites_only_metadata(tmp_path):
    bag_dir = tmp_path / 'stale'
    with BagWriter(bag_dir) as bag:
        _add_topics(bag)
        bag.write(SURFACE_NORMAL.name, serialize_message(_normal(0)), T0_NS)
    mcap_bytes = (bag_dir / 'stale_0.mcap').read_bytes()
    path = bag_dir / 'metadata.yaml'
    document = yaml.safe_load(path.read_text())
    document['rosbag2_bagfile_information']['message_count'] = 0
    path.write_text(yaml.safe_dump(document))

    result = repair_bag(bag_dir)
    assert (result.was_complete, result.rewritten, result.backup) == (True, True, None)
    assert (bag_dir / 'stale_0.mcap').read_bytes() == mcap_bytes
    assert read_metadata(bag_dir)['message_count'] == 1
    assert sorted(p.name for p in bag_dir.iterdir()) == ['metadata.yaml', 'stale_0.mcap']


def test_info_reports_a_bag_that_was_not_closed(tmp_path, capsys):
    _write_flushed_bag(tmp_path / 'open')
    assert cli.main(['bag', 'info', str(tmp_path / 'open')]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[1] == 'metadata.yaml lists 0 messages'
    assert lines[2].startswith('open_0.mcap: 30 readable messages in 3 chunks over 0.029 s, '
                               'not closed (the file ends without a footer)')
    assert lines[3:] == [f'  {SURFACE_NORMAL.name} (geometry_msgs/msg/Vector3Stamped): 15',
                         f'  {BEAM_VOLTAGE.name} (sensor_msgs/msg/JointState): 15']


# --- what is not a readable bag ------------------------------------------------------------

def _foreign_mcap(path):
    """A valid MCAP file of JSON messages, as a non-ROS tool writes it."""
    with open(path, 'wb') as stream:
        writer = Writer(stream)
        writer.start(profile='', library='other')
        schema = writer.register_schema('Point', 'jsonschema', b'{"type": "object"}')
        channel = writer.register_channel('/points', 'json', schema)
        writer.add_message(channel, log_time=1, data=b'{"x": 1}', publish_time=1)
        writer.finish()


def _make_bag_with(tmp_path, content):
    """A bag directory whose MCAP file is replaced by ``content`` (bytes or a writer)."""
    bag_dir = tmp_path / 'broken'
    BagWriter(bag_dir).close()
    path = bag_dir / 'broken_0.mcap'
    if callable(content):
        content(path)
    else:
        path.write_bytes(content)
    return bag_dir


BROKEN = {
    'empty': (b'', r'broken_0\.mcap is empty: no MCAP header was ever written'),
    'cut in the magic': (b'\x89MCA', r'truncated inside the MCAP magic \(4 bytes\)'),
    'cut in the header': (b'\x89MCAP0\r\n\x01\x40\x00\x00\x00\x00\x00\x00\x00ros',
                          r'truncated inside its MCAP header \(20 bytes\)'),
    'not MCAP': (b'SQLite format 3\x00' + bytes(100), r'is not an MCAP file'),
    'foreign MCAP': (_foreign_mcap, r'is not ROS 2 data: topic /points has message encoding '
                                    r"'json', not 'cdr'"),
}


@pytest.mark.parametrize('case', BROKEN)
def test_an_unreadable_mcap_file_is_a_one_line_error(tmp_path, capsys, case):
    content, message = BROKEN[case]
    bag_dir = _make_bag_with(tmp_path, content)
    with pytest.raises(BagError, match=message) as raised:
        list(read_messages(bag_dir))
    assert '\n' not in str(raised.value)
    for action in ('info', 'repair'):
        assert cli.main(['bag', action, str(bag_dir)]) == 2
        captured = capsys.readouterr()
        (line,) = captured.err.splitlines()
        assert line.startswith(f'sphere-twin bag {action}: error: ') and not captured.out
        assert str(raised.value) in line


def test_a_directory_without_metadata_is_a_one_line_error(tmp_path, capsys):
    (tmp_path / 'plain').mkdir()
    (tmp_path / 'plain' / 'plain_0.mcap').write_bytes(b'\x89MCAP0\r\n')
    with pytest.raises(BagError, match=r'plain is not a bag: it has no metadata\.yaml$'):
        list(read_messages(tmp_path / 'plain'))
    for target in ('plain', 'missing'):
        for action in ('info', 'repair'):
            assert cli.main(['bag', action, str(tmp_path / target)]) == 2
            (line,) = capsys.readouterr().err.splitlines()
            assert line.startswith(f'sphere-twin bag {action}: error: ') and 'is not a bag' in line


# --- a recorder killed for real ------------------------------------------------------------

READY_TIMEOUT_S = 20.0
MATCH_TIMEOUT_S = 10.0
FLUSH_PERIOD_S = 0.2
PUBLISH_PERIOD_S = 0.005
RUN_BEFORE_KILL_S = 2.0
# The recorder's flush timer may run late on a busy machine; beyond this the test fails.
FLUSH_LATENESS_ALLOWED_S = 1.0


@pytest.fixture
def publisher_node(ros_nodes, monkeypatch):
    monkeypatch.setenv(DISCOVERY_RANGE_VAR, 'LOCALHOST')
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=ros_nodes.domain_id)
    node = Node('crash_test_publisher', context=context)
    yield node
    node.destroy_node()
    rclpy.try_shutdown(context=context)


@pytest.mark.ros
def test_a_recorder_killed_mid_run_loses_at_most_its_last_flush_period(
        ros_nodes, publisher_node, tmp_path, record_property, capsys):
    bag_dir = tmp_path / 'killed'
    recorder = ros_nodes.start('recorder', parameter_args(
        output_dir=str(bag_dir), flush_period_s=FLUSH_PERIOD_S,
        topics=f'[{SURFACE_NORMAL.name}]'))
    recorder.wait_for_output(f'recording 1 topics to {bag_dir}', READY_TIMEOUT_S)
    publisher = publisher_node.create_publisher(
        Vector3Stamped, SURFACE_NORMAL.name, SURFACE_NORMAL.qos.to_profile())
    deadline = time.monotonic() + MATCH_TIMEOUT_S
    while publisher.get_subscription_count() < 1:
        assert time.monotonic() < deadline, 'the recorder never subscribed'
        time.sleep(0.05)

    # Stream until the recorder reports its first message on the topic (discovery has
    # completed both ways), then for RUN_BEFORE_KILL_S more.
    sent_at = []
    start = None
    while start is None or time.monotonic() - start < RUN_BEFORE_KILL_S:
        publisher.publish(_normal(len(sent_at)))
        sent_at.append(time.monotonic())
        if start is None and f'recording {SURFACE_NORMAL.name}' in recorder.stderr_text():
            start, first_after_match = time.monotonic(), len(sent_at)
        assert start is not None or time.monotonic() < deadline + READY_TIMEOUT_S
        time.sleep(PUBLISH_PERIOD_S)
    recorder.send_signal(signal.SIGKILL)
    killed_at = time.monotonic()
    assert stop(recorder) == -signal.SIGKILL
    publisher.wait_for_all_acked(Duration(seconds=0))

    readable = [deserialize_message(m.data, Vector3Stamped).header.stamp.sec
                for m in read_messages(bag_dir)]
    # What survives is gap-free and in order: every completed chunk, from the first message
    # the recorder received (at the latest the one it announced) on.
    assert readable == list(range(readable[0], readable[0] + len(readable)))
    assert readable[0] < first_after_match
    lost = len(sent_at) - 1 - readable[-1]
    record_property('published', len(sent_at))
    record_property('lost', lost)
    with capsys.disabled():
        print(f'\nSIGKILL after {len(sent_at)} messages at {1 / PUBLISH_PERIOD_S:g} Hz '
              f'(flush period {FLUSH_PERIOD_S} s, 768 KiB chunks): {len(readable)} readable, '
              f'{lost} lost at the end, {readable[0]} sent before the recorder had matched')
    # The bag did hold data when killed ...
    assert not has_footer(bag_dir / 'killed_0.mcap')
    assert read_metadata(bag_dir)['message_count'] == 0
    # ... and lost only what arrived since the last completed chunk.
    must_survive = sum(t < killed_at - FLUSH_PERIOD_S - FLUSH_LATENESS_ALLOWED_S
                       for t in sent_at)
    assert must_survive > 0
    assert len(readable) >= must_survive

    assert cli.main(['bag', 'repair', str(bag_dir)]) == 0
    with Reader(bag_dir) as reader:
        assert reader.message_count == len(readable)
        recovered = [JAZZY.deserialize_cdr(d, c.msgtype).header.stamp.sec
                     for c, _, d in reader.messages()]
    assert recovered == readable
