"""Rebuild a bag whose recorder died: a complete MCAP file and a metadata.yaml that agree.

A recorder killed outright (SIGKILL, power loss) leaves an MCAP file without summary and
footer, perhaps ending inside a chunk, and a metadata.yaml that lists the topics but not
the messages. :func:`repair_bag` reads every record that survived
(:func:`~sphere_twin.bag.reader.scan_mcap`), writes them into a new, cleanly closed MCAP
file with :class:`~sphere_twin.bag.writer.BagWriter` (schemas, channel QoS and type hashes
copied, not regenerated), and writes metadata.yaml with the recovered counts, start time and
duration. The damaged file is kept beside it as ``<file>.bak`` unless asked otherwise.

Nothing here needs ROS: ``sphere-twin bag repair`` calls it directly.
"""

import dataclasses
import os
import shutil
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import yaml
from mcap.records import Channel

from sphere_twin.bag import format as bag_format
from sphere_twin.bag.reader import (
    BagError,
    McapScan,
    check_ros2,
    read_metadata,
    scan_mcap,
    storage_files,
)
from sphere_twin.bag.writer import COMPRESSIONS, DEFAULT_COMPRESSION, BagWriter

BACKUP_SUFFIX = '.bak'
WORK_DIR_NAME = '.repair'


@dataclasses.dataclass(frozen=True)
class RepairResult:
    """What :func:`repair_bag` found and did.

    Attributes
    ----------
    bag_dir : pathlib.Path
    file_name : str
        The MCAP file of the bag.
    was_complete : bool
        Whether the file already had its footer (then only metadata.yaml may be rewritten).
    rewritten : bool
        Whether anything was written.
    message_count : int
        Messages in the repaired bag.
    topic_counts : dict of str to int
        Messages per topic in the repaired bag.
    listed_count : int
        Messages metadata.yaml listed before the repair.
    chunk_count : int
        Complete chunks read.
    stop_reason : str or None
        Where and why reading the damaged file stopped.
    backup : pathlib.Path or None
        The damaged file, if kept.
    """

    bag_dir: Path
    file_name: str
    was_complete: bool
    rewritten: bool
    message_count: int
    topic_counts: dict[str, int]
    listed_count: int
    chunk_count: int
    stop_reason: str | None
    backup: Path | None

    def summary(self) -> str:
        """One line for the command line."""
        topics = len(self.topic_counts)
        if not self.rewritten:
            return (f'{self.bag_dir}: intact, {self.message_count} messages on {topics} '
                    'topics; nothing to repair')
        if self.was_complete:
            return (f'{self.bag_dir}: MCAP file intact; metadata.yaml rewritten with '
                    f'{self.message_count} messages on {topics} topics (it listed '
                    f'{self.listed_count})')
        kept = f'; damaged file kept as {self.backup.name}' if self.backup else ''
        return (f'repaired {self.bag_dir}: {self.message_count} messages on {topics} topics '
                f'recovered from {self.chunk_count} complete chunks (metadata.yaml listed '
                f'{self.listed_count}; {self.stop_reason}){kept}')


def _qos_of(channel: Channel, listed_topics: Mapping[str, Mapping[str, Any]]) -> list[Any]:
    """Offered QoS mappings of a channel: its own metadata, else metadata.yaml's entry."""
    try:
        return bag_format.parse_offered_qos_yaml(
            channel.metadata.get('offered_qos_profiles', ''))
    except (ValueError, TypeError, AttributeError, yaml.YAMLError):
        listed = listed_topics.get(channel.topic, {})
        profiles = listed.get('offered_qos_profiles', [])
        return profiles if isinstance(profiles, list) else []


def _topic_counts(scan: McapScan) -> dict[str, int]:
    counts: dict[str, int] = {}
    for channel_id, count in scan.message_counts().items():
        topic = scan.channels[channel_id].topic
        counts[topic] = counts.get(topic, 0) + count
    return counts


def _metadata_agrees(metadata: Mapping[str, Any], counts: Mapping[str, int]) -> bool:
    listed = {t['topic_metadata']['name']: t.get('message_count')
              for t in metadata.get('topics_with_message_count') or []
              if isinstance(t, dict) and isinstance(t.get('topic_metadata'), dict)}
    return listed == counts and metadata.get('message_count') == sum(counts.values())


def _write_bag(scan: McapScan, work_dir: Path, file_name: str,
               metadata: Mapping[str, Any]) -> BagWriter:
    """Write the scanned records as a complete bag in ``work_dir``."""
    listed_topics = {t['topic_metadata']['name']: t['topic_metadata']
                     for t in metadata.get('topics_with_message_count') or []
                     if isinstance(t, dict) and isinstance(t.get('topic_metadata'), dict)}
    compression = (next(iter(scan.compressions)) if len(scan.compressions) == 1
                   else DEFAULT_COMPRESSION)
    if compression not in COMPRESSIONS:
        compression = DEFAULT_COMPRESSION
    custom_data = metadata.get('custom_data')
    writer = BagWriter(work_dir, compression=compression, file_name=file_name,
                       ros_distro=metadata.get('ros_distro') or None,
                       custom_data=custom_data if isinstance(custom_data, dict) else None)
    with writer:
        for channel in scan.channels.values():
            if writer.has_topic(channel.topic):
                continue
            schema = scan.schemas[channel.schema_id]
            writer.add_topic(channel.topic, schema.name, _qos_of(channel, listed_topics),
                             channel.metadata.get('topic_type_hash', ''),
                             message_definition=schema.data.decode('utf-8', 'replace'))
        for message in scan.messages:
            writer.write(scan.channels[message.channel_id].topic, message.data,
                         message.log_time, message.publish_time, message.sequence)
    return writer


def repair_bag(bag_dir: str | os.PathLike[str], backup: bool = True) -> RepairResult:
    """Make a bag whose recorder died readable by every rosbag2 reader.

    Parameters
    ----------
    bag_dir : str or os.PathLike
        The bag directory (with metadata.yaml and one MCAP file).
    backup : bool
        Keep the damaged MCAP file as ``<file>.bak`` in the bag directory.

    Returns
    -------
    RepairResult

    Raises
    ------
    BagError
        If ``bag_dir`` is not a bag, holds more than one storage file, or its MCAP file is
        empty, foreign or unreadable from the start.
    """
    bag_dir = Path(bag_dir)
    metadata = read_metadata(bag_dir)
    paths = storage_files(bag_dir)
    if len(paths) != 1:
        raise BagError(f'{bag_dir}: repair handles bags of one storage file; metadata.yaml '
                       f'lists {len(paths)}')
    (path,) = paths
    scan = scan_mcap(path)
    check_ros2(path, scan.schemas, scan.channels)
    counts = _topic_counts(scan)
    listed_count = metadata.get('message_count') or 0
    if scan.complete and _metadata_agrees(metadata, counts):
        return RepairResult(bag_dir, path.name, True, False, len(scan.messages), counts,
                            listed_count, scan.chunk_count, None, None)

    work_dir = bag_dir / WORK_DIR_NAME
    if work_dir.exists():
        shutil.rmtree(work_dir)
    try:
        _write_bag(scan, work_dir, path.name, metadata)
        backup_path: Path | None = None
        if not scan.complete:
            if backup:
                backup_path = path.with_name(path.name + BACKUP_SUFFIX)
                os.replace(path, backup_path)
            os.replace(work_dir / path.name, path)
        os.replace(work_dir / bag_format.METADATA_FILENAME,
                   bag_dir / bag_format.METADATA_FILENAME)
    finally:
        shutil.rmtree(work_dir, ignore_errors=True)
    return RepairResult(bag_dir, path.name, scan.complete, True, len(scan.messages), counts,
                        listed_count, scan.chunk_count, scan.stop_reason, backup_path)
