"""The recorder node: the contract's topics to a rosbag2-compatible bag, as rosbag2 records.

Subscribes to every topic of :data:`msg_defs.topics.ALL_TOPICS` (or the ``topics``
parameter) without deserializing (``raw=True``), so the CDR bytes go to the bag exactly as
they came off the wire, and writes them with :class:`sphere_twin.bag.writer.BagWriter`:
``<output_dir>/metadata.yaml`` (rosbag2 version 9) and ``<output_dir>/<name>_0.mcap``.

As ``ros2 bag record`` does, a topic enters the bag with its first message, described by the
QoS profiles its publishers offer and the type hash they announce (both from the ROS graph);
the log time of a message is when it was received (node clock), its publish time the
sender's source timestamp. On SIGINT or SIGTERM the node takes the messages already
delivered to it, finishes the MCAP file and metadata.yaml, and prints
``recorded N messages on K topics to <dir>``. Chunks are completed every ``flush_period_s``,
so a recorder killed outright loses at most that much.
"""

from __future__ import annotations

import datetime
import functools
import signal
import sys
import time
from pathlib import Path
from types import FrameType
from typing import Any

from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import QoSProfile

from msg_defs.topics import Topic, topic_by_name
from sphere_twin.bag import format as bag_format
from sphere_twin.bag.writer import BagWriter
from sphere_twin.node_runtime.parameter_specs import StartupError, declare_node_parameters
from sphere_twin.node_runtime.ros_env import run_node
from sphere_twin.nodes.parameters import DEFAULT_BAG_PARENT, RECORDER_PARAMETERS

# Depth of the recorder's subscriptions. History does not affect QoS compatibility; a
# deeper one than the contract's keeps a message that arrives while a chunk is being
# compressed from being overwritten before it is taken.
RECORDER_HISTORY_DEPTH = 1000
# On shutdown, messages already delivered are taken until none has come for this long.
DRAIN_QUIET_S = 0.1
DRAIN_MAX_S = 2.0
# Longest time between two looks at the stop flag.
SPIN_POLL_S = 0.1


def default_output_dir(now: datetime.datetime | None = None) -> str:
    """``bags/run_<UTC time>``, e.g. ``bags/run_20250101T120000Z``."""
    now = now or datetime.datetime.now(datetime.UTC)
    return str(Path(DEFAULT_BAG_PARENT) / f'run_{now.strftime("%Y%m%dT%H%M%SZ")}')


def summary_line(message_count: int, topic_count: int, path: str | Path) -> str:
    """The recorder's last line of output."""
    return f'recorded {message_count} messages on {topic_count} topics to {path}'


def open_bag(output_dir: str, compression: str, chunk_size_bytes: int) -> BagWriter:
    """A new bag in ``output_dir``.

    Raises
    ------
    StartupError
        For a directory that is not empty, or one that cannot be made or written: the path
        and the reason in words (an OSError's first argument is its number, which the one line
        of a start-up error would otherwise print alone).
    """
    try:
        return BagWriter(output_dir, compression=compression, chunk_size_bytes=chunk_size_bytes)
    except FileExistsError as error:
        raise StartupError(f'parameter output_dir: {error}: give a new or empty '
                           'directory (a bag is never overwritten)') from None
    except OSError as error:
        reason = error.strerror or str(error)
        culprit = '' if error.filename in (None, output_dir) else f'{error.filename}: '
        raise StartupError(f'cannot create output_dir {output_dir}: {culprit}{reason}') from None


class RecorderNode(Node):
    """Records contract topics to a bag.

    Parameters
    ----------
    **node_kwargs
        Passed to ``rclpy.node.Node`` (e.g. ``context``, ``parameter_overrides``).

    Attributes
    ----------
    writer : sphere_twin.bag.writer.BagWriter
        The bag; closed by :meth:`finish` or :meth:`destroy_node`.
    topics : tuple of msg_defs.topics.Topic
        What is subscribed.

    Raises
    ------
    ValueError
        For a bad parameter, such as a topic that is not in the contract, or an output
        directory that exists and is not empty (a StartupError).
    """

    def __init__(self, **node_kwargs: Any) -> None:
        super().__init__('recorder', **node_kwargs)
        p = self._declare_parameters()
        try:
            self.topics = tuple(topic_by_name(name) for name in p['topics'] if name)
        except KeyError as error:
            raise ValueError(f'parameter topics: {error.args[0]}') from None
        self.writer = open_bag(p['output_dir'] or default_output_dir(), p['compression'],
                               p['chunk_size_bytes'])
        for topic in self.topics:
            self.create_subscription(topic.msg_type, topic.name,
                                     functools.partial(self.on_message, topic),
                                     topic.qos.to_profile(min_depth=RECORDER_HISTORY_DEPTH),
                                     raw=True)
        if p['flush_period_s'] > 0:
            self.create_timer(p['flush_period_s'], self.on_flush_timer)
        self.get_logger().info(
            f'domain id {self.context.get_domain_id()}; recording {len(self.topics)} topics '
            f'to {self.writer.path} ({p["compression"]} chunks)')

    def _declare_parameters(self) -> dict[str, Any]:
        return declare_node_parameters(self, RECORDER_PARAMETERS)

    # --- recording ----------------------------------------------------------------------

    def on_message(self, topic: Topic, data: bytes, message_info: dict[str, Any]) -> None:
        """Write one serialized message; the first one on a topic adds the topic."""
        if self.writer.closed:
            return
        log_time_ns = self.get_clock().now().nanoseconds
        publish_time_ns = message_info.get('source_timestamp') or log_time_ns
        if not self.writer.has_topic(topic.name):
            self._add_topic(topic)
        self.writer.write(topic.name, data, log_time_ns, publish_time_ns)

    def offered_qos(self, topic: Topic) -> tuple[list[dict[str, Any]], str]:
        """QoS profiles and type hash the publishers of ``topic`` offer, from the graph.

        Returns
        -------
        (list of dict, str)
            One :func:`~sphere_twin.bag.format.qos_to_dict` mapping per publisher of the
            contract's type, and their type hash. Without such publishers (already gone),
            the contract's profile and the hash our own subscription announces.
        """
        type_name = bag_format.type_name_of(topic.msg_type)
        publishers = [info for info in self.get_publishers_info_by_topic(topic.name)
                      if info.topic_type == type_name]
        if publishers:
            return ([bag_format.qos_to_dict(info.qos_profile) for info in publishers],
                    str(publishers[0].topic_type_hash))
        own = [info for info in self.get_subscriptions_info_by_topic(topic.name)
               if info.node_name == self.get_name()
               and info.node_namespace == self.get_namespace()]
        type_hash = str(own[0].topic_type_hash) if own else ''
        profile = topic.qos.to_profile()
        return [bag_format.qos_to_dict(QoSProfile(
            history=profile.history, depth=profile.depth, reliability=profile.reliability,
            durability=profile.durability))], type_hash

    def _add_topic(self, topic: Topic) -> None:
        qos_dicts, type_hash = self.offered_qos(topic)
        self.writer.add_topic(topic.name, bag_format.type_name_of(topic.msg_type), qos_dicts,
                              type_hash)
        self.get_logger().info(
            f'recording {topic.name} ({bag_format.type_name_of(topic.msg_type)}) offered by '
            f'{len(qos_dicts)} publisher(s)')

    def on_flush_timer(self) -> None:
        """Complete the current chunk, so that a crash loses at most one flush period."""
        if not self.writer.closed:
            self.writer.flush()

    # --- shutdown -----------------------------------------------------------------------

    def spin_until(self, stop: StopRequest) -> None:
        """Record until ``stop`` is requested, then :meth:`drain`.

        Parameters
        ----------
        stop : StopRequest
            Polled between executor steps of at most :data:`SPIN_POLL_S`.
        """
        executor = SingleThreadedExecutor(context=self.context)
        executor.add_node(self)
        try:
            while self.context.ok() and not stop.requested:
                executor.spin_once(timeout_sec=SPIN_POLL_S)
            self.drain(executor)
        finally:
            executor.remove_node(self)
            executor.shutdown(timeout_sec=0)

    def drain(self, executor: Any, quiet_s: float = DRAIN_QUIET_S,
              max_s: float = DRAIN_MAX_S) -> None:
        """Take the messages already delivered to this node, until none comes for ``quiet_s``
        (at most ``max_s``); does nothing once the context is shut down."""
        hard_deadline = time.monotonic() + max_s
        quiet_deadline = time.monotonic() + quiet_s
        while (self.context.ok() and not self.writer.closed
               and time.monotonic() < min(quiet_deadline, hard_deadline)):
            before = self.writer.message_count
            executor.spin_once(timeout_sec=quiet_s)
            if self.writer.message_count != before:
                quiet_deadline = time.monotonic() + quiet_s

    def finish(self) -> str:
        """Close the bag and return :func:`summary_line`."""
        self.writer.close()
        return summary_line(self.writer.message_count, self.writer.topic_count,
                            self.writer.path)

    def destroy_node(self) -> None:
        """Close the bag, then destroy the node."""
        self.writer.close()
        super().destroy_node()


class StopRequest:
    """SIGINT and SIGTERM as a flag rather than an exception.

    rclpy's own handlers shut the context down at once, dropping messages already delivered
    but not yet taken, and ``KeyboardInterrupt`` could strike in the middle of writing a
    chunk. The recorder therefore starts rclpy without its signal handlers and installs these
    instead; :meth:`RecorderNode.spin_until` polls the flag, so the node stops within
    :data:`SPIN_POLL_S` and every write completes.

    Attributes
    ----------
    signal_name : str or None
        The first stop signal received.
    """

    def __init__(self) -> None:
        self.signal_name: str | None = None

    @property
    def requested(self) -> bool:
        """Whether a stop signal has arrived."""
        return self.signal_name is not None

    def install(self) -> StopRequest:
        """Handle SIGINT and SIGTERM with :meth:`request`; returns ``self``."""
        for signum in (signal.SIGINT, signal.SIGTERM):
            signal.signal(signum, self.request)
        return self

    def request(self, signum: int = signal.SIGINT, _frame: FrameType | None = None) -> None:
        """Ask the recorder to stop (the signal handler)."""
        if self.signal_name is None:
            self.signal_name = signal.Signals(signum).name


def main(args: list[str] | None = None) -> int:
    """Run the recorder until SIGINT or SIGTERM.

    Exit status 2 when it cannot start (a bad parameter, a bag directory that is not empty)
    and 1 when it could not write (a full disk, a missing message definition), each with one
    line on stderr; the summary line is printed whenever the bag was opened.
    """
    stop = StopRequest()
    return run_node(RecorderNode, args, spin=lambda node: node.spin_until(stop),
                    farewell=RecorderNode.finish, name='recorder',
                    parameters=RECORDER_PARAMETERS,
                    own_signal_handling=stop.install)


if __name__ == '__main__':
    sys.exit(main())
