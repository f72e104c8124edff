"""The rosbag2 bag layout as ROS 2 Jazzy's ``ros2 bag record -s mcap`` writes it.

Three things must agree for readers to accept a bag, and each is produced here, once:

``metadata.yaml``
    rosbag2 metadata version 9 (:func:`bag_metadata`, :func:`metadata_yaml_text`): keys in
    the order rosbag2_storage's YAML encoder emits them, offered QoS profiles as a YAML list
    of mappings with lower-case policy names, ``compression_format``/``compression_mode``
    empty because MCAP compresses inside its chunks.
MCAP channels
    ``message_encoding`` ``cdr`` and metadata ``offered_qos_profiles`` (the same profiles as
    YAML text, :func:`offered_qos_yaml`) and ``topic_type_hash`` (:func:`channel_metadata`).
    Readers such as ``rosbags`` match metadata.yaml topics to channels by topic, type *and*
    QoS, and silently yield nothing for a topic whose two QoS descriptions differ; both are
    therefore derived from one list of :func:`qos_to_dict` mappings.
MCAP schemas
    Encoding ``ros2msg``; the data is the full message definition
    (:func:`message_definition`): the type's ``.msg`` text, then for every type it depends
    on (depth first, each once, dependencies of one type in sorted order) a newline, a line
    of 80 ``=``, a line ``MSG: <type as written in the field>`` and that type's ``.msg``
    text, exactly as rosbag2_cpp's LocalMessageDefinitionSource builds it.

Nothing here imports rclpy; a QoS profile is passed in as any object with rclpy
``QoSProfile``'s attributes.
"""

import functools
import importlib.util
import os
import re
import sys
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import yaml

from msg_defs.device import NS_PER_S

METADATA_FILENAME = 'metadata.yaml'
METADATA_VERSION = 9
STORAGE_IDENTIFIER = 'mcap'
SERIALIZATION_FORMAT = 'cdr'
SCHEMA_ENCODING = 'ros2msg'
MCAP_PROFILE = 'ros2'
# The MCAP metadata record in which rosbag2 repeats the bag metadata when it closes a file.
MCAP_METADATA_NAME = 'rosbag2'
MCAP_SERIALIZED_METADATA_KEY = 'serialized_metadata'
DEFAULT_ROS_DISTRO = 'jazzy'
DEFINITION_DELIMITER = '=' * 80
# rosbag2 starts a bag at the latest representable time and lowers it with every message,
# so a bag without messages keeps this starting time.
EMPTY_BAG_STARTING_TIME_NS = 2**63 - 1

QOS_KEYS = ('history', 'depth', 'reliability', 'durability', 'deadline', 'lifespan',
            'liveliness', 'liveliness_lease_duration', 'avoid_ros_namespace_conventions')
BAG_METADATA_KEYS = ('version', 'storage_identifier', 'duration', 'starting_time',
                     'message_count', 'topics_with_message_count', 'compression_format',
                     'compression_mode', 'relative_file_paths', 'files', 'custom_data',
                     'ros_distro')

# rosbag2_cpp's pattern for the type of a field in a .msg file ("pkg/Type" in
# "pkg/Type[] name"); '^' is the start of the text only, as in std::regex.
_MSG_FIELD_TYPE = re.compile(r'(?:^|\n)\s*([a-zA-Z0-9_/]+)(?:\[[^\]]*\])?\s+')
_PRIMITIVE_TYPES = frozenset((
    'bool', 'byte', 'char', 'float32', 'float64', 'int8', 'uint8', 'int16', 'uint16',
    'int32', 'uint32', 'int64', 'uint64', 'string'))
_ROS_NAME = '[a-zA-Z][a-zA-Z0-9_]*'
_TYPE_WITHOUT_NAMESPACE = re.compile(f'^({_ROS_NAME})/({_ROS_NAME})$')
_TYPE_WITH_NAMESPACE = re.compile(f'^({_ROS_NAME})/({_ROS_NAME})/({_ROS_NAME})$')


class MessageDefinitionNotFoundError(FileNotFoundError):
    """No ``.msg`` file was found for a message type."""


# --- YAML as rosbag2 (yaml-cpp) emits it --------------------------------------------------

class _RosbagYamlDumper(yaml.SafeDumper):
    """Block style like yaml-cpp: sequences inside mappings indented, '' as "", None as ~."""

    def increase_indent(self, flow: bool = False, indentless: bool = False) -> None:
        return super().increase_indent(flow, False)


def _represent_str(dumper: _RosbagYamlDumper, value: str) -> yaml.ScalarNode:
    style = '"' if value == '' else None
    return dumper.represent_scalar('tag:yaml.org,2002:str', value, style=style)


def _represent_none(dumper: _RosbagYamlDumper, _value: None) -> yaml.ScalarNode:
    return dumper.represent_scalar('tag:yaml.org,2002:null', '~')


_RosbagYamlDumper.add_representer(str, _represent_str)
_RosbagYamlDumper.add_representer(type(None), _represent_none)


def dump_yaml(data: Any) -> str:
    """YAML text of ``data`` in yaml-cpp's block layout, key order kept, no final newline."""
    text = yaml.dump(data, Dumper=_RosbagYamlDumper, sort_keys=False,
                     default_flow_style=False, allow_unicode=True, width=2**16)
    return text.rstrip('\n')


# --- QoS ---------------------------------------------------------------------------------

def _time_dict(duration: Any) -> dict[str, int]:
    ns = int(duration.nanoseconds)
    return {'sec': ns // NS_PER_S, 'nsec': ns % NS_PER_S}


def qos_to_dict(profile: Any) -> dict[str, Any]:
    """A QoS profile as rosbag2 metadata version 9 records it.

    Parameters
    ----------
    profile : rclpy.qos.QoSProfile
        Or any object with its attributes (policies are enums, durations have
        ``nanoseconds``), e.g. ``TopicEndpointInfo.qos_profile`` of a discovered publisher.

    Returns
    -------
    dict
        Keys :data:`QOS_KEYS` in that order; policies as lower-case names (``keep_last``,
        ``reliable``, ``transient_local``, ``automatic``, ``unknown``, ...), durations as
        ``{'sec': s, 'nsec': ns}`` (an infinite duration is ``sec: 9223372036,
        nsec: 854775807``, as RMW_DURATION_INFINITE).
    """
    return {
        'history': profile.history.name.lower(),
        'depth': int(profile.depth),
        'reliability': profile.reliability.name.lower(),
        'durability': profile.durability.name.lower(),
        'deadline': _time_dict(profile.deadline),
        'lifespan': _time_dict(profile.lifespan),
        'liveliness': profile.liveliness.name.lower(),
        'liveliness_lease_duration': _time_dict(profile.liveliness_lease_duration),
        'avoid_ros_namespace_conventions': bool(profile.avoid_ros_namespace_conventions),
    }


def offered_qos_yaml(qos_dicts: Sequence[Mapping[str, Any]]) -> str:
    """The ``offered_qos_profiles`` text of an MCAP channel: the same list as YAML.

    Parameters
    ----------
    qos_dicts : sequence of dict
        From :func:`qos_to_dict`; the same objects go into metadata.yaml.

    Returns
    -------
    str
        A YAML block sequence (``'[]'`` for none, as rosbag2 writes an empty list).
    """
    if not qos_dicts:
        return '[]'
    return dump_yaml([dict(d) for d in qos_dicts])


def parse_offered_qos_yaml(text: str) -> list[Any]:
    """Inverse of :func:`offered_qos_yaml`: the list of QoS mappings ('' gives [])."""
    if not text:
        return []
    loaded = yaml.safe_load(text)
    if not isinstance(loaded, list):
        raise ValueError(f'offered_qos_profiles is not a YAML list: {text!r}')
    return loaded


# --- topics and metadata -------------------------------------------------------------------

def type_name_of(msg_type: type) -> str:
    """``pkg/msg/Type`` of a generated message class (e.g. ``nav_msgs/msg/Odometry``)."""
    package, namespace = msg_type.__module__.split('.')[:2]
    return f'{package}/{namespace}/{msg_type.__name__}'


def topic_metadata(name: str, type_name: str, qos_dicts: Iterable[Mapping[str, Any]],
                   type_description_hash: str = '') -> dict[str, Any]:
    """The ``topic_metadata`` mapping of one topic in metadata.yaml (version 9).

    Parameters
    ----------
    name : str
        Topic name.
    type_name : str
        ``pkg/msg/Type``.
    qos_dicts : sequence of dict
        Offered QoS profiles from :func:`qos_to_dict`.
    type_description_hash : str
        ``RIHS01_<hex>``, or '' where unknown (rosbag2 writes '' too).
    """
    return {
        'name': name,
        'type': type_name,
        'serialization_format': SERIALIZATION_FORMAT,
        'offered_qos_profiles': [dict(d) for d in qos_dicts],
        'type_description_hash': type_description_hash,
    }


def channel_metadata(qos_dicts: Sequence[Mapping[str, Any]],
                     type_description_hash: str = '') -> dict[str, str]:
    """The metadata of a topic's MCAP channel, as rosbag2_storage_mcap writes it."""
    return {
        'offered_qos_profiles': offered_qos_yaml(qos_dicts),
        'topic_type_hash': type_description_hash,
    }


def bag_metadata(topics: Sequence[tuple[Mapping[str, Any], int]], relative_file_path: str,
                 starting_time_ns: int | None, duration_ns: int, ros_distro: str | None = None,
                 custom_data: Mapping[str, str] | None = None) -> dict[str, Any]:
    """The ``rosbag2_bagfile_information`` mapping of a single-file MCAP bag.

    Parameters
    ----------
    topics : sequence of (dict, int)
        ``(topic_metadata(...), message_count)`` per topic, in the order to list them.
    relative_file_path : str
        File name of the MCAP file inside the bag directory.
    starting_time_ns : int or None
        Receive time of the first message (ns since the epoch); None for a bag without
        messages.
    duration_ns : int
        Last receive time minus the first.
    ros_distro : str, optional
        ``ROS_DISTRO`` of the environment, else :data:`DEFAULT_ROS_DISTRO`.
    custom_data : dict of str to str, optional
        Written as ``~`` when empty, as rosbag2 does.

    Returns
    -------
    dict
        Keys :data:`BAG_METADATA_KEYS` in that order.
    """
    message_count = sum(count for _, count in topics)
    starting = {'nanoseconds_since_epoch': int(
        EMPTY_BAG_STARTING_TIME_NS if starting_time_ns is None else starting_time_ns)}
    duration = {'nanoseconds': int(duration_ns)}
    if ros_distro is None:
        ros_distro = os.environ.get('ROS_DISTRO') or DEFAULT_ROS_DISTRO
    return {
        'version': METADATA_VERSION,
        'storage_identifier': STORAGE_IDENTIFIER,
        'duration': duration,
        'starting_time': starting,
        'message_count': message_count,
        'topics_with_message_count': [
            {'topic_metadata': metadata, 'message_count': int(count)}
            for metadata, count in topics],
        'compression_format': '',
        'compression_mode': '',
        'relative_file_paths': [relative_file_path],
        'files': [{
            'path': relative_file_path,
            'starting_time': dict(starting),
            'duration': dict(duration),
            'message_count': message_count,
        }],
        'custom_data': dict(custom_data) if custom_data else None,
        'ros_distro': ros_distro,
    }


def metadata_yaml_text(metadata: Mapping[str, Any]) -> str:
    """Text of ``metadata.yaml`` for a :func:`bag_metadata` mapping (ends with a newline)."""
    return dump_yaml({'rosbag2_bagfile_information': metadata}) + '\n'


# --- message definitions -------------------------------------------------------------------

def _split_type_name(type_name: str) -> tuple[str, str, str]:
    """``(package, namespace, name)`` of ``pkg/Type`` (namespace ``msg``) or ``pkg/ns/Type``."""
    match = _TYPE_WITHOUT_NAMESPACE.match(type_name)
    if match:
        return match[1], 'msg', match[2]
    match = _TYPE_WITH_NAMESPACE.match(type_name)
    if match:
        return match[1], match[2], match[3]
    raise ValueError(f'not a message type name (pkg/msg/Type or pkg/Type): {type_name!r}')


def package_share_candidates(package: str) -> list[Path]:
    """Directories that may be ``share/<package>``, most authoritative first.

    The ament index (``AMENT_PREFIX_PATH``, set by sourcing a ROS installation), then the
    ``share`` directory of the prefix the package's Python module is installed in
    (``<prefix>/lib/pythonX.Y/site-packages/<package>`` -> ``<prefix>/share/<package>``;
    this covers a virtual environment with ROS from PyPI wheels), then
    ``<sys.prefix>/share/<package>``.
    """
    candidates: list[Path] = []
    if os.environ.get('AMENT_PREFIX_PATH'):
        try:
            from ament_index_python.packages import get_package_share_directory

            candidates.append(Path(get_package_share_directory(package)))
        except (ImportError, LookupError, OSError, ValueError):
            pass
    try:
        spec = importlib.util.find_spec(package)
    except (ImportError, ValueError):
        spec = None
    if spec is not None and spec.origin:
        module_dir = Path(spec.origin).resolve().parent
        if module_dir.parent.name in ('site-packages', 'dist-packages'):
            candidates.append(module_dir.parents[3] / 'share' / package)
    candidates.append(Path(sys.prefix) / 'share' / package)
    unique: list[Path] = []
    for candidate in candidates:
        if candidate not in unique:
            unique.append(candidate)
    return unique


def find_msg_file(type_name: str) -> Path:
    """Path of the ``.msg`` file defining ``type_name`` (``pkg/msg/Type`` or ``pkg/Type``).

    Raises
    ------
    MessageDefinitionNotFoundError
        Naming every place looked in.
    ValueError
        If ``type_name`` is not a message type name.
    """
    package, namespace, name = _split_type_name(type_name)
    tried: list[str] = []
    for share in package_share_candidates(package):
        path = share / namespace / f'{name}.msg'
        if path.is_file():
            return path
        tried.append(str(path))
    raise MessageDefinitionNotFoundError(
        f'no .msg definition of {type_name}; looked in: {", ".join(tried)}. Install the '
        f'{package} package (or source the ROS installation that has it).')


def msg_dependencies(text: str, package: str) -> list[str]:
    """Types a ``.msg`` text refers to, as rosbag2 finds them (sorted, as a std::set).

    A type without a package (``Pose`` in a geometry_msgs file) is prefixed with
    ``package``; others are kept as written (``std_msgs/Header``).
    """
    dependencies: set[str] = set()
    for match in _MSG_FIELD_TYPE.finditer(text):
        field_type = match[1]
        if field_type in _PRIMITIVE_TYPES:
            continue
        dependencies.add(field_type if '/' in field_type else f'{package}/{field_type}')
    return sorted(dependencies)


@functools.cache
def _msg_text(type_name: str) -> str:
    return find_msg_file(type_name).read_text(encoding='utf-8')


def message_definition(type_name: str) -> str:
    """Full ``ros2msg`` definition of ``type_name`` with its dependencies, as rosbag2 writes it.

    Parameters
    ----------
    type_name : str
        ``pkg/msg/Type``.

    Returns
    -------
    str
        The type's ``.msg`` text; then, depth first and each type once, for every type it
        uses: ``'\\n' + '=' * 80 + '\\n' + 'MSG: ' + dependency + '\\n' +`` its text (and its
        own dependencies). The dependency is named as the field wrote it, so
        ``nav_msgs/msg/Odometry`` has ``MSG: std_msgs/Header``.

    Raises
    ------
    MessageDefinitionNotFoundError
        If the ``.msg`` file of the type or of any dependency is missing.
    """
    seen: set[str] = set()

    def append_recursive(name: str) -> str:
        text = _msg_text(name)
        result = text
        for dependency in msg_dependencies(text, _split_type_name(name)[0]):
            if dependency not in seen:
                seen.add(dependency)
                result += f'\n{DEFINITION_DELIMITER}\nMSG: {dependency}\n'
                result += append_recursive(dependency)
        return result

    return append_recursive(type_name)
