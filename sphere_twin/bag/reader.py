"""Read a bag written by :class:`~sphere_twin.bag.writer.BagWriter` or by ``ros2 bag record``.

A deliberately small reader for our own tools (report, player): the metadata, and the
messages of one MCAP bag in log-time order as raw CDR bytes, with
:func:`deserialize` to turn them into message objects.

Crash safety
------------
A recorder that dies without closing its bag leaves an MCAP file without summary and
footer, possibly ending inside a record. Such a file is read by :func:`scan_mcap`, which
walks the records from the start and stops cleanly at the first incomplete or unreadable
one; every chunk completed before the crash is readable. :func:`read_messages` does this by
itself for a file without a footer, and :mod:`sphere_twin.bag.repair` rewrites such a bag
into a complete one.

Every way a path can fail to be a readable bag (no metadata.yaml, an empty, truncated or
corrupt file, a file that is not MCAP or not ROS 2 data) raises :class:`BagError` with a
one-line message.
"""

import dataclasses
import importlib
import io
import os
import struct
from collections.abc import Iterable, Iterator, Mapping
from pathlib import Path
from typing import IO, Any

import yaml
from mcap.data_stream import ReadDataStream
from mcap.exceptions import McapError
from mcap.opcode import Opcode
from mcap.reader import make_reader
from mcap.records import Channel, Chunk, Footer, Header, McapRecord, Message, Metadata, Schema
from mcap.stream_reader import breakup_chunk

try:
    from zstandard import ZstdError
except ImportError:  # mcap then cannot read zstd chunks at all
    ZstdError = McapError  # type: ignore[misc, assignment]  # the stand-in for a missing class

from sphere_twin.bag import format as bag_format

MCAP_MAGIC = b'\x89MCAP0\r\n'
# An MCAP record starts with a 1-byte opcode and an 8-byte little-endian body length.
RECORD_PREFIX = struct.Struct('<BQ')
# Footer record (prefix + 8 + 8 + 4 bytes) and the closing magic.
FOOTER_SIZE = RECORD_PREFIX.size + 20
# Records longer than this are taken as corruption rather than allocated.
MAX_RECORD_BYTES = 4 * 2**30
COMPRESSION_NAMES = {'': 'none', 'zstd': 'zstd', 'lz4': 'lz4'}
_RECORD_CLASSES: dict[int, type[McapRecord]] = {
    Opcode.HEADER: Header, Opcode.SCHEMA: Schema, Opcode.CHANNEL: Channel,
    Opcode.CHUNK: Chunk, Opcode.METADATA: Metadata, Opcode.FOOTER: Footer}
# Exceptions the mcap record parsers and decompressors raise on damaged bytes (lz4 raises
# RuntimeError).
_DAMAGE = (McapError, ZstdError, ValueError, struct.error, EOFError, IndexError, KeyError,
           UnicodeDecodeError, RuntimeError)


class BagError(ValueError):
    """A path that is not a readable bag (no metadata, unsupported storage, missing file, an
    empty, truncated, corrupt or foreign MCAP file); the message is one line."""


@dataclasses.dataclass(frozen=True)
class RecordedMessage:
    """One message of a bag.

    Attributes
    ----------
    topic : str
    type_name : str
        ``pkg/msg/Type``.
    log_time_ns : int
        When the recorder received it.
    publish_time_ns : int
        When it was sent.
    data : bytes
        The CDR-serialized message.
    """

    topic: str
    type_name: str
    log_time_ns: int
    publish_time_ns: int
    data: bytes


@dataclasses.dataclass
class McapScan:
    """What :func:`scan_mcap` could read of one MCAP file.

    Attributes
    ----------
    path : pathlib.Path
    profile : str
        The header's profile (``ros2`` for rosbag2).
    schemas : dict of int to mcap.records.Schema
    channels : dict of int to mcap.records.Channel
        In the order they appear in the file.
    messages : list of mcap.records.Message
        In file order.
    metadata : list of mcap.records.Metadata
    compressions : set of str
        Compression of the chunks read (``'none'``, ``'zstd'``, ``'lz4'``).
    chunk_count : int
        Chunks read completely.
    complete : bool
        Whether the file ends with a footer (a cleanly closed file).
    readable_bytes : int
        Offset up to which the file was read.
    file_size : int
    stop_reason : str or None
        Why reading stopped before the footer (``None`` for a complete file).
    """

    path: Path
    profile: str = ''
    schemas: dict[int, Schema] = dataclasses.field(default_factory=dict)
    channels: dict[int, Channel] = dataclasses.field(default_factory=dict)
    messages: list[Message] = dataclasses.field(default_factory=list)
    metadata: list[Metadata] = dataclasses.field(default_factory=list)
    compressions: set[str] = dataclasses.field(default_factory=set)
    chunk_count: int = 0
    complete: bool = False
    readable_bytes: int = 0
    file_size: int = 0
    stop_reason: str | None = None

    def type_name(self, channel_id: int) -> str:
        """``pkg/msg/Type`` of a channel ('' if it has no schema)."""
        schema = self.schemas.get(self.channels[channel_id].schema_id)
        return schema.name if schema else ''

    def message_counts(self) -> dict[int, int]:
        """Readable messages per channel id."""
        counts = dict.fromkeys(self.channels, 0)
        for message in self.messages:
            counts[message.channel_id] += 1
        return counts


def read_metadata(bag_dir: str | os.PathLike[str]) -> dict[str, Any]:
    """The ``rosbag2_bagfile_information`` mapping of a bag's metadata.yaml.

    Raises
    ------
    BagError
        If there is no metadata.yaml or it is not rosbag2 metadata.
    """
    path = Path(bag_dir) / bag_format.METADATA_FILENAME
    if not Path(bag_dir).is_dir():
        raise BagError(f'{bag_dir} is not a bag: no such directory')
    try:
        document = yaml.safe_load(path.read_text(encoding='utf-8'))
    except FileNotFoundError:
        raise BagError(f'{bag_dir} is not a bag: it has no {bag_format.METADATA_FILENAME}') \
            from None
    except (OSError, UnicodeDecodeError) as error:
        raise BagError(f'{bag_dir} is not a bag: cannot read {path}: {error}') from None
    except yaml.YAMLError as error:
        problem = str(error).replace('\n', ' ')
        raise BagError(f'{path} is not valid YAML: {problem}') from None
    if not isinstance(document, dict) or not isinstance(
            document.get('rosbag2_bagfile_information'), dict):
        raise BagError(f'{path} has no rosbag2_bagfile_information')
    return document['rosbag2_bagfile_information']


def storage_files(bag_dir: str | os.PathLike[str]) -> list[Path]:
    """Paths of the bag's MCAP files, as metadata.yaml lists them.

    Raises
    ------
    BagError
        If the storage is not MCAP or a listed file is missing.
    """
    metadata = read_metadata(bag_dir)
    if metadata.get('storage_identifier') != bag_format.STORAGE_IDENTIFIER:
        raise BagError(f'{bag_dir}: storage {metadata.get("storage_identifier")!r} is not '
                       f'supported, only {bag_format.STORAGE_IDENTIFIER!r}')
    paths = [Path(bag_dir) / Path(p).name for p in metadata.get('relative_file_paths') or []]
    if not paths:
        raise BagError(f'{bag_dir}: metadata.yaml lists no storage files')
    missing = [str(p) for p in paths if not p.is_file()]
    if missing:
        raise BagError(f'{bag_dir}: storage files missing: {", ".join(missing)}')
    return paths


# --- scanning an MCAP file record by record ----------------------------------------------

def _parse(record_class: Any, body: bytes) -> Any:
    return record_class.read(ReadDataStream(io.BytesIO(body)))


def _check_start(path: Path, stream: IO[bytes], file_size: int) -> Header:
    """Read the magic and the header record; BagError unless this is the start of an MCAP."""
    if file_size == 0:
        raise BagError(f'{path} is empty: no MCAP header was ever written')
    magic = stream.read(len(MCAP_MAGIC))
    if magic != MCAP_MAGIC[:len(magic)]:
        raise BagError(f'{path} is not an MCAP file (it does not start with the MCAP magic)')
    if len(magic) < len(MCAP_MAGIC):
        raise BagError(f'{path} is truncated inside the MCAP magic ({file_size} bytes)')
    prefix = stream.read(RECORD_PREFIX.size)
    if len(prefix) < RECORD_PREFIX.size:
        raise BagError(f'{path} is truncated before its MCAP header ({file_size} bytes)')
    opcode, length = RECORD_PREFIX.unpack(prefix)
    if opcode != Opcode.HEADER or length > MAX_RECORD_BYTES:
        raise BagError(f'{path} is not a valid MCAP file: it does not begin with a header')
    body = stream.read(length)
    if len(body) < length:
        raise BagError(f'{path} is truncated inside its MCAP header ({file_size} bytes)')
    try:
        return _parse(Header, body)
    except _DAMAGE:
        raise BagError(f'{path} is not a valid MCAP file: its header is corrupt') from None


def scan_mcap(path: str | os.PathLike[str]) -> McapScan:
    """Read every complete record of an MCAP file from its start, without its summary.

    Reading stops at the footer, or cleanly at the first record that is cut off by the end
    of the file, implausibly long, of a reserved opcode, or whose chunk does not decompress
    or fails its CRC: what a crash or a partly written disk block leaves.

    Parameters
    ----------
    path : str or os.PathLike

    Returns
    -------
    McapScan

    Raises
    ------
    BagError
        If the file cannot be opened, is empty, does not start with the MCAP magic and a
        complete header record.
    """
    path = Path(path)
    try:
        stream = open(path, 'rb')  # noqa: SIM115
    except OSError as error:
        raise BagError(f'cannot open {path}: {error.strerror}') from None
    with stream:
        file_size = path.stat().st_size
        header = _check_start(path, stream, file_size)
        scan = McapScan(path, profile=header.profile, file_size=file_size)
        while True:
            offset = stream.tell()
            scan.readable_bytes = offset
            prefix = stream.read(RECORD_PREFIX.size)
            if not prefix:
                scan.stop_reason = 'the file ends without a footer'
                break
            if len(prefix) < RECORD_PREFIX.size:
                scan.stop_reason = f'the file ends inside a record at byte {offset}'
                break
            opcode, length = RECORD_PREFIX.unpack(prefix)
            if opcode == 0 or length > MAX_RECORD_BYTES:
                scan.stop_reason = f'unreadable bytes at byte {offset}'
                break
            if length > file_size - offset - RECORD_PREFIX.size:
                scan.stop_reason = f'the file ends inside a record at byte {offset}'
                break
            body = stream.read(length)
            reason = _take_record(scan, opcode, body, offset)
            if reason is not None:
                scan.stop_reason = reason
                break
            if opcode == Opcode.FOOTER:
                scan.readable_bytes = stream.tell()
                scan.complete = True
                break
    return scan


def _take_record(scan: McapScan, opcode: int, body: bytes, offset: int) -> str | None:
    """Add one record's contents to ``scan``; the reason to stop if it is damaged."""
    record_class = _RECORD_CLASSES.get(opcode)
    if record_class is None:
        return None
    try:
        record = _parse(record_class, body)
        if opcode == Opcode.CHUNK:
            inner = breakup_chunk(record, validate_crc=True)
    except _DAMAGE:
        return f'a damaged {Opcode(opcode).name.lower()} record at byte {offset}'
    if opcode == Opcode.CHUNK:
        scan.chunk_count += 1
        scan.compressions.add(COMPRESSION_NAMES.get(record.compression, record.compression))
        for item in inner:
            _take_plain_record(scan, item)
    elif opcode == Opcode.METADATA:
        scan.metadata.append(record)
    else:
        _take_plain_record(scan, record)
    return None


def _take_plain_record(scan: McapScan, record: McapRecord) -> None:
    if isinstance(record, Schema):
        scan.schemas.setdefault(record.id, record)
    elif isinstance(record, Channel):
        scan.channels.setdefault(record.id, record)
    elif isinstance(record, Message) and record.channel_id in scan.channels:
        scan.messages.append(record)


def has_footer(path: str | os.PathLike[str]) -> bool:
    """Whether an MCAP file ends with a footer and the magic, as a cleanly closed file does."""
    path = Path(path)
    try:
        size = path.stat().st_size
        if size < 2 * len(MCAP_MAGIC) + FOOTER_SIZE:
            return False
        with open(path, 'rb') as stream:
            stream.seek(size - FOOTER_SIZE - len(MCAP_MAGIC))
            tail = stream.read()
    except OSError:
        return False
    return tail[0] == Opcode.FOOTER and tail.endswith(MCAP_MAGIC)


def check_ros2(path: str | os.PathLike[str], schemas: Mapping[int, Schema],
               channels: Mapping[int, Channel]) -> None:
    """BagError unless every channel carries CDR messages with ``ros2msg`` schemas."""
    for channel in channels.values():
        if channel.message_encoding != bag_format.SERIALIZATION_FORMAT:
            raise BagError(f'{path} is not ROS 2 data: topic {channel.topic} has message '
                           f'encoding {channel.message_encoding!r}, not '
                           f'{bag_format.SERIALIZATION_FORMAT!r}')
        schema = schemas.get(channel.schema_id)
        if schema is None or schema.encoding != bag_format.SCHEMA_ENCODING:
            encoding = 'no schema' if schema is None else f'schema encoding {schema.encoding!r}'
            raise BagError(f'{path} is not ROS 2 data: topic {channel.topic} has {encoding}, '
                           f'not {bag_format.SCHEMA_ENCODING!r}')


# --- messages ----------------------------------------------------------------------------

def _indexed_messages(path: Path, wanted: list[str] | None) -> Iterator[RecordedMessage]:
    """Messages of a complete file through its summary and chunk indexes."""
    with open(path, 'rb') as stream:
        reader = make_reader(stream)
        summary = reader.get_summary()
        if summary is not None:
            check_ros2(path, summary.schemas, summary.channels)
        for schema, channel, message in reader.iter_messages(
                topics=wanted, log_time_order=True):
            yield RecordedMessage(channel.topic, schema.name if schema else '',
                                  message.log_time, message.publish_time, message.data)


def _scanned_messages(path: Path, wanted: list[str] | None) -> Iterator[RecordedMessage]:
    """Messages of a file without a usable summary, read by :func:`scan_mcap`."""
    scan = scan_mcap(path)
    check_ros2(path, scan.schemas, scan.channels)
    selected = [m for m in scan.messages
                if wanted is None or scan.channels[m.channel_id].topic in wanted]
    selected.sort(key=lambda m: m.log_time)
    for message in selected:
        yield RecordedMessage(scan.channels[message.channel_id].topic,
                              scan.type_name(message.channel_id), message.log_time,
                              message.publish_time, message.data)


def read_messages(bag_dir: str | os.PathLike[str],
                  topics: Iterable[str] | None = None) -> Iterator[RecordedMessage]:
    """Iterate over a bag's messages in log-time order.

    A file closed cleanly is read through its index; one without a footer (a recorder that
    was killed) is scanned, yielding the messages of every chunk completed before the end.

    Parameters
    ----------
    bag_dir : str or os.PathLike
    topics : iterable of str, optional
        Only these topics; all by default.

    Yields
    ------
    RecordedMessage

    Raises
    ------
    BagError
        If the bag, or one of its files, cannot be read at all.
    """
    wanted = None if topics is None else list(topics)
    for path in storage_files(bag_dir):
        if has_footer(path):
            messages = _indexed_messages(path, wanted)
        else:
            messages = _scanned_messages(path, wanted)
        try:
            yield from messages
        except BagError:
            raise
        except _DAMAGE as error:
            problem = str(error).replace('\n', ' ') or type(error).__name__
            raise BagError(f'{path} is corrupt: {problem}; try `sphere-twin bag repair '
                           f'{bag_dir}`') from None


def message_class(type_name: str) -> type[Any]:
    """The generated Python class of ``pkg/msg/Type`` (the package must be installed)."""
    package, namespace, name = type_name.split('/')
    return getattr(importlib.import_module(f'{package}.{namespace}'), name)


def deserialize(message: RecordedMessage) -> Any:
    """The message object of a :class:`RecordedMessage` (needs rclpy, not a ROS graph)."""
    from rclpy.serialization import deserialize_message

    return deserialize_message(message.data, message_class(message.type_name))


def in_current_contract(message: RecordedMessage) -> RecordedMessage:
    """``message`` as the topic contract carries it today: a programme status recorded before
    the contract moved to action_msgs (docs/twin.md, "Contract changes") is re-encoded, so a
    player republishes old bags on the types today's nodes subscribe to; every other message
    is returned as it is."""
    from msg_defs.conversions import (
        LEGACY_PROGRAMME_STATUS_TYPE,
        legacy_programme_status_from_cdr,
        programme_event_to_msg,
        programme_events_from_msg,
    )
    from msg_defs.topics import PROGRAMME_STATUS

    if message.type_name != LEGACY_PROGRAMME_STATUS_TYPE:
        return message
    from rclpy.serialization import serialize_message

    events = programme_events_from_msg(legacy_programme_status_from_cdr(message.data))
    status_list = [status for event in events
                   for status in programme_event_to_msg(event).status_list]
    current = PROGRAMME_STATUS.msg_type(status_list=status_list)
    return dataclasses.replace(message, type_name=bag_format.type_name_of(
                                   PROGRAMME_STATUS.msg_type), data=serialize_message(current))
