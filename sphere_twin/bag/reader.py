"""Read a bag written by :class:`~sphere_twin.bag.writer.BagWriter` or by ``ros2 bag record``.

A deliberately small reader for our own tools (report, player): the metadata, and the
messages of one MCAP bag in log-time order as raw CDR bytes, with
:func:`deserialize` to turn them into message objects.
"""

import dataclasses
import importlib
from pathlib import Path

import yaml
from mcap.reader import make_reader

from sphere_twin.bag import format as bag_format


class BagError(ValueError):
    """A path that is not a readable bag (no metadata, unsupported storage, missing file)."""


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


def read_metadata(bag_dir):
    """The ``rosbag2_bagfile_information`` mapping of a bag's metadata.yaml.

    Raises
    ------
    BagError
        If there is no metadata.yaml or it is not rosbag2 metadata.
    """
    path = Path(bag_dir) / bag_format.METADATA_FILENAME
    try:
        document = yaml.safe_load(path.read_text(encoding='utf-8'))
    except OSError as error:
        raise BagError(f'{bag_dir} is not a bag: cannot read {path}: {error}') from None
    except yaml.YAMLError as error:
        raise BagError(f'{path} is not valid YAML: {error}') from None
    if not isinstance(document, dict) or 'rosbag2_bagfile_information' not in document:
        raise BagError(f'{path} has no rosbag2_bagfile_information')
    return document['rosbag2_bagfile_information']


def storage_files(bag_dir):
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
    paths = [Path(bag_dir) / Path(p).name for p in metadata.get('relative_file_paths', [])]
    missing = [str(p) for p in paths if not p.is_file()]
    if missing:
        raise BagError(f'{bag_dir}: storage files missing: {", ".join(missing)}')
    return paths


def read_messages(bag_dir, topics=None):
    """Iterate over a bag's messages in log-time order.

    Parameters
    ----------
    bag_dir : str or os.PathLike
    topics : iterable of str, optional
        Only these topics; all by default.

    Yields
    ------
    RecordedMessage
    """
    wanted = None if topics is None else list(topics)
    for path in storage_files(bag_dir):
        with open(path, 'rb') as stream:
            reader = make_reader(stream)
            for schema, channel, message in reader.iter_messages(
                    topics=wanted, log_time_order=True):
                yield RecordedMessage(channel.topic, schema.name if schema else '',
                                      message.log_time, message.publish_time, message.data)


def message_class(type_name):
    """The generated Python class of ``pkg/msg/Type`` (the package must be installed)."""
    package, namespace, name = type_name.split('/')
    return getattr(importlib.import_module(f'{package}.{namespace}'), name)


def deserialize(message):
    """The message object of a :class:`RecordedMessage` (needs rclpy, not a ROS graph)."""
    from rclpy.serialization import deserialize_message

    return deserialize_message(message.data, message_class(message.type_name))
