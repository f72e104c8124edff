"""Write serialized messages to a rosbag2 bag directory (metadata.yaml + one MCAP file).

:class:`BagWriter` knows nothing of DDS: it takes CDR bytes with their times, which is what
the recorder node hands it and what a test can hand it directly.

Examples
--------
>>> with BagWriter('bags/example') as bag:  # doctest: +SKIP
...     bag.add_topic('/sphere/surface_normal', 'geometry_msgs/msg/Vector3Stamped', [qos])
...     bag.write('/sphere/surface_normal', cdr_bytes, log_time_ns, publish_time_ns)
"""

from __future__ import annotations

import dataclasses
import importlib.metadata
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, Self

from mcap.writer import CompressionType, Writer

from sphere_twin.bag import format as bag_format

if TYPE_CHECKING:
    from msg_defs.topics import Topic

COMPRESSIONS = {'zstd': CompressionType.ZSTD, 'lz4': CompressionType.LZ4,
                'none': CompressionType.NONE}
DEFAULT_COMPRESSION = 'zstd'
# The chunk size of the MCAP C++ writer that rosbag2 uses (768 KiB).
DEFAULT_CHUNK_SIZE_BYTES = 768 * 1024


def _library_string() -> str:
    versions: list[str] = []
    for distribution in ('sphere_twin', 'mcap'):
        try:
            versions.append(f'{distribution} {importlib.metadata.version(distribution)}')
        except importlib.metadata.PackageNotFoundError:
            versions.append(distribution)
    return '; '.join(versions)


def mcap_file_name(bag_dir: str | os.PathLike[str]) -> str:
    """``<name>_0.mcap``, the bag's only storage file, for a bag directory named ``name``."""
    return f'{Path(bag_dir).name}_0.mcap'


@dataclasses.dataclass
class _TopicRecord:
    metadata: dict[str, Any]
    channel_id: int
    message_count: int = 0
    sequence: int = 0


class BagWriter:
    """A bag being written.

    The directory and ``metadata.yaml`` (no topics, no messages) exist as soon as the writer
    is built, so even a recording killed before its first message leaves a recognisable bag.
    ``metadata.yaml`` is rewritten whenever a topic is added and on :meth:`close`; messages go
    into the MCAP file as they are written, a chunk at a time.

    Parameters
    ----------
    path : str or os.PathLike
        Bag directory; created (with its parents). Must not exist, or be empty.
    compression : {'zstd', 'lz4', 'none'}
        Compression of the MCAP chunks.
    chunk_size_bytes : int
        Uncompressed size at which a chunk is completed and written.
    ros_distro : str, optional
        For metadata.yaml; ``ROS_DISTRO`` or ``jazzy`` by default.
    file_name : str, optional
        Name of the MCAP file; :func:`mcap_file_name` by default.
    custom_data : dict of str to str, optional
        metadata.yaml's ``custom_data``.

    Raises
    ------
    FileExistsError
        If ``path`` exists and is not an empty directory.
    ValueError
        For an unknown compression or a non-positive chunk size.
    """

    def __init__(self, path: str | os.PathLike[str], compression: str = DEFAULT_COMPRESSION,
                 chunk_size_bytes: int = DEFAULT_CHUNK_SIZE_BYTES, ros_distro: str | None = None,
                 file_name: str | None = None,
                 custom_data: Mapping[str, str] | None = None) -> None:
        if compression not in COMPRESSIONS:
            raise ValueError(f'unknown compression {compression!r}; '
                             f'choose one of {", ".join(COMPRESSIONS)}')
        if chunk_size_bytes <= 0:
            raise ValueError(f'chunk size must be positive, got {chunk_size_bytes}')
        self.path = Path(path)
        if self.path.exists() and not self.path.is_dir():
            raise FileExistsError(f'bag directory {self.path} is a file, not a directory')
        if self.path.exists() and any(self.path.iterdir()):
            raise FileExistsError(f'bag directory {self.path} already exists and is not empty')
        self.path.mkdir(parents=True, exist_ok=True)
        self.file_name = file_name or mcap_file_name(self.path)
        self.compression = compression
        self.ros_distro = ros_distro
        self.custom_data = dict(custom_data or {})
        self._topics: dict[str, _TopicRecord] = {}
        self._schema_ids: dict[str, int] = {}
        self._start_ns: int | None = None
        self._end_ns: int | None = None
        self._closed = False
        # Stays open until close(); flush() pushes everything written so far to the file.
        self._stream = open(self.path / self.file_name, 'wb')  # noqa: SIM115
        self._mcap = Writer(self._stream, chunk_size=chunk_size_bytes,
                            compression=COMPRESSIONS[compression])
        self._mcap.start(profile=bag_format.MCAP_PROFILE, library=_library_string())
        # The header on disk at once: a recorder killed before its first chunk leaves an
        # MCAP file that is recognisably one, not an empty file.
        self._stream.flush()
        self._write_metadata_file()

    # --- state ------------------------------------------------------------------------

    @property
    def message_count(self) -> int:
        """Messages written so far."""
        return sum(t.message_count for t in self._topics.values())

    @property
    def topic_count(self) -> int:
        """Topics added so far."""
        return len(self._topics)

    @property
    def closed(self) -> bool:
        """Whether :meth:`close` has run."""
        return self._closed

    def has_topic(self, name: str) -> bool:
        """Whether ``name`` has been added."""
        return name in self._topics

    def metadata(self) -> dict[str, Any]:
        """The bag metadata as metadata.yaml holds it (see :func:`format.bag_metadata`)."""
        topics = [(t.metadata, t.message_count) for t in self._topics.values()]
        duration = (0 if self._start_ns is None or self._end_ns is None  # set together
                    else self._end_ns - self._start_ns)
        return bag_format.bag_metadata(topics, self.file_name, self._start_ns, duration,
                                       self.ros_distro, self.custom_data)

    # --- writing ----------------------------------------------------------------------

    def add_contract_topic(self, topic: Topic) -> None:
        """Add a topic of the contract (:class:`msg_defs.topics.Topic`) with the QoS the
        contract gives it: what a bag written without live publishers offers."""
        self.add_topic(topic.name, bag_format.type_name_of(topic.msg_type),
                       [bag_format.qos_to_dict(topic.qos.to_profile())])

    def add_topic(self, name: str, type_name: str, qos_dicts: Sequence[Mapping[str, Any]],
                  type_description_hash: str = '', message_definition: str | None = None,
                  ) -> None:
        """Add a topic: its schema (once per type), its channel and its metadata.yaml entry.

        Parameters
        ----------
        name : str
            Topic name.
        type_name : str
            ``pkg/msg/Type``; its ``.msg`` definition must be installed.
        qos_dicts : sequence of dict
            Offered QoS profiles (:func:`format.qos_to_dict`); written identically to the
            channel and to metadata.yaml.
        type_description_hash : str
            ``RIHS01_...``, or '' if unknown.
        message_definition : str, optional
            The schema text to write (e.g. copied from another bag); by default
            :func:`format.message_definition` builds it from the installed ``.msg`` files.
            Used by the first topic of each type only.

        Raises
        ------
        ValueError
            If the topic was already added.
        format.MessageDefinitionNotFoundError
            If the type's definition cannot be found.
        """
        self._check_open()
        if name in self._topics:
            raise ValueError(f'topic {name} was already added to {self.path}')
        if type_name not in self._schema_ids:
            definition = (bag_format.message_definition(type_name)
                          if message_definition is None else message_definition)
            self._schema_ids[type_name] = self._mcap.register_schema(
                type_name, bag_format.SCHEMA_ENCODING, definition.encode())
        channel_id = self._mcap.register_channel(
            name, bag_format.SERIALIZATION_FORMAT, self._schema_ids[type_name],
            bag_format.channel_metadata(qos_dicts, type_description_hash))
        self._topics[name] = _TopicRecord(
            bag_format.topic_metadata(name, type_name, qos_dicts, type_description_hash),
            channel_id)
        self._write_metadata_file()

    def write(self, topic: str, data: bytes, log_time_ns: int, publish_time_ns: int | None = None,
              sequence: int | None = None) -> None:
        """Write one serialized message.

        Parameters
        ----------
        topic : str
            An added topic.
        data : bytes
            The CDR-serialized message.
        log_time_ns : int
            Receive time (ns); metadata.yaml's times are taken from these.
        publish_time_ns : int, optional
            Send time (ns); ``log_time_ns`` if omitted.
        sequence : int, optional
            The MCAP sequence number; by default the topic's message count so far plus one.
        """
        self._check_open()
        record = self._topics.get(topic)
        if record is None:
            raise KeyError(f'topic {topic} has not been added to {self.path}')
        record.sequence += 1
        self._mcap.add_message(
            record.channel_id, log_time=int(log_time_ns), data=bytes(data),
            publish_time=int(log_time_ns if publish_time_ns is None else publish_time_ns),
            sequence=record.sequence if sequence is None else int(sequence))
        record.message_count += 1
        if self._start_ns is None or self._end_ns is None:  # set together
            self._start_ns = self._end_ns = int(log_time_ns)
        else:
            self._start_ns = min(self._start_ns, int(log_time_ns))
            self._end_ns = max(self._end_ns, int(log_time_ns))

    def flush(self) -> None:
        """Complete the current chunk (if it has messages) and hand everything written so far
        to the operating system, so that it survives the end of this process."""
        self._check_open()
        self._mcap.flush()

    def close(self) -> None:
        """Finish the MCAP file (last chunk, rosbag2 metadata record, summary, footer) and
        write the final metadata.yaml. Does nothing if already closed."""
        if self._closed:
            return
        self._closed = True
        try:
            metadata = self.metadata()
            self._mcap.add_metadata(bag_format.MCAP_METADATA_NAME, {
                bag_format.MCAP_SERIALIZED_METADATA_KEY: bag_format.dump_yaml(metadata)})
            self._mcap.finish()
        finally:
            self._stream.close()
            self._write_metadata_file()

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    # --- internals --------------------------------------------------------------------

    def _check_open(self) -> None:
        if self._closed:
            raise ValueError(f'bag {self.path} is closed')

    def _write_metadata_file(self) -> None:
        # Replace atomically, so a reader (or a crash) never sees a half-written file.
        target = self.path / bag_format.METADATA_FILENAME
        partial = target.with_name(target.name + '.tmp')
        partial.write_text(bag_format.metadata_yaml_text(self.metadata()), encoding='utf-8')
        os.replace(partial, target)
