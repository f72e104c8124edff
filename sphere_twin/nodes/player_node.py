"""The player node: a bag's messages republished onto their topics at their recorded timing.

Like ``ros2 bag play``: every message of the bag (or of the ``topics`` chosen) is published
as the serialized CDR bytes it was recorded as, with the topic contract's QoS (a topic
outside the contract gets the QoS its publishers offered when it was recorded), at its log
time relative to the start of playback divided by ``rate`` (2 plays twice as fast).
``start_offset_s`` skips the first seconds of the bag. /clock is published too: the bag's own
/clock messages if it has any, otherwise the log time of each message just before that
message, so nodes with ``use_sim_time`` follow the recording's time.

When the bag has been played the node waits for its reliable messages to be acknowledged,
prints ``played N messages`` and exits; with ``loop`` it starts over until stopped. The
timing is computed by :func:`playback_plan`, which needs no ROS graph. The bag is read into
memory when the node starts; a bag left by a killed recorder plays its completed chunks.
"""

import dataclasses
import sys
import time
from collections.abc import Collection, Mapping, Sequence
from typing import Any

from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from msg_defs.device import NS_PER_S
from msg_defs.topics import ALL_TOPICS, CLOCK
from sphere_twin.bag import format as bag_format
from sphere_twin.bag.locate import locate_bag
from sphere_twin.bag.reader import (
    RecordedMessage,
    in_current_contract,
    message_class,
    read_messages,
    read_metadata,
)
from sphere_twin.node_runtime.parameter_specs import StartupError, declare_node_parameters
from sphere_twin.node_runtime.ros_env import run_node
from sphere_twin.nodes.parameters import MAX_RATE, MIN_RATE, PLAYER_PARAMETERS

# Longest single sleep, so that a stop signal is handled promptly.
SLEEP_SLICE_S = 0.1
ACK_TIMEOUT_S = 5.0
DEFAULT_QOS_DEPTH = 10
# Wall seconds between two progress lines while a bag plays: a long bag (the example, 33 s
# recorded) otherwise plays in silence until its last line. The CLI's period
# (sphere_twin.run_analysis.PROGRESS_PERIOD_S), not imported from there: that module would add
# a second to the node's start.
PROGRESS_PERIOD_S = 5.0


@dataclasses.dataclass(frozen=True)
class PlaybackItem:
    """One publication of the player.

    Attributes
    ----------
    due_s : float
        Wall-clock seconds after the start of playback at which it is published.
    topic : str
    data : bytes or None
        The recorded CDR bytes; None for a /clock tick the player makes itself.
    log_time_ns : int
        The recorded log time (for a made-up /clock tick: the time it publishes).
    """

    topic: str
    due_s: float
    data: bytes | None
    log_time_ns: int


# Through a gap in a bag without /clock, made-up ticks come at least this often (recorded
# time): ros2 bag play's --clock publishes at a fixed rate for the same reason.
CLOCK_GAP_TICK_S = 0.1
CLOCK_GAP_TICK_NS = round(CLOCK_GAP_TICK_S * NS_PER_S)


def playback_plan(messages: Sequence[RecordedMessage], rate: float = 1.0,
                  start_offset_s: float = 0.0, topics: Collection[str] | None = None,
                  publish_clock: bool = True) -> list[PlaybackItem]:
    """What the player publishes and when.

    Parameters
    ----------
    messages : sequence of sphere_twin.bag.reader.RecordedMessage
        The whole bag, in log-time order.
    rate : float
        Playback speed: a message recorded ``dt`` after the starting point is published
        ``dt / rate`` after the start of playback.
    start_offset_s : float
        Messages logged earlier than this after the bag's first message are skipped; the
        starting point is the first message's log time plus this.
    topics : collection of str, optional
        Only these topics; all by default.
    publish_clock : bool
        If the bag has no /clock messages, add a /clock tick with each message's log time
        just before it, and ticks at least every ``CLOCK_GAP_TICK_S`` of recorded time through
        a gap, so that nodes on simulated time see it run on. A bag that has /clock messages
        plays those (if /clock is selected).

    Returns
    -------
    list of PlaybackItem
        In publication order.

    Raises
    ------
    ValueError
        For a rate or start offset out of range.
    """
    if not MIN_RATE <= rate <= MAX_RATE:
        raise ValueError(f'rate must lie in [{MIN_RATE}, {MAX_RATE}], got {rate}')
    if start_offset_s < 0:
        raise ValueError(f'start_offset_s must not be negative, got {start_offset_s}')
    if not messages:
        return []
    start_ns = messages[0].log_time_ns + round(start_offset_s * NS_PER_S)
    make_clock = publish_clock and not any(m.topic == CLOCK.name for m in messages)
    plan: list[PlaybackItem] = []
    for message in messages:
        if message.log_time_ns < start_ns or (topics is not None and message.topic not in topics):
            continue
        due_s = (message.log_time_ns - start_ns) / NS_PER_S / rate
        if make_clock:
            previous_ns = plan[-1].log_time_ns if plan else message.log_time_ns
            for tick_ns in range(previous_ns + CLOCK_GAP_TICK_NS, message.log_time_ns,
                                 CLOCK_GAP_TICK_NS):
                plan.append(PlaybackItem(CLOCK.name, (tick_ns - start_ns) / NS_PER_S / rate,
                                         None, tick_ns))
            plan.append(PlaybackItem(CLOCK.name, due_s, None, message.log_time_ns))
        plan.append(PlaybackItem(message.topic, due_s, message.data, message.log_time_ns))
    return plan


def recorded_qos(topic_metadata: Mapping[str, Any]) -> QoSProfile:
    """A QoS profile from a metadata.yaml topic entry's first offered profile.

    Discovered profiles do not announce history and depth; those become keep-last
    :data:`DEFAULT_QOS_DEPTH`.
    """
    profiles = topic_metadata.get('offered_qos_profiles') or []
    profile = profiles[0] if profiles and isinstance(profiles[0], dict) else {}
    reliable = profile.get('reliability', 'reliable') != 'best_effort'
    latched = profile.get('durability') == 'transient_local'
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=int(profile.get('depth') or 0) or DEFAULT_QOS_DEPTH,
        reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
        durability=(DurabilityPolicy.TRANSIENT_LOCAL if latched
                    else DurabilityPolicy.VOLATILE))


def check_selection(bag: str, messages: Sequence[RecordedMessage], start_offset_s: float,
                    topics: Collection[str] | None) -> None:
    """Refuse a start offset past the bag's end, or topics it does not hold: either would
    play nothing and exit 0, as if the bag had been played.

    Raises
    ------
    StartupError
        Naming the bag's duration, or its topics.
    """
    if not messages:
        return
    duration_s = (messages[-1].log_time_ns - messages[0].log_time_ns) / NS_PER_S
    if start_offset_s > duration_s:
        raise StartupError(f'parameter start_offset_s = {start_offset_s:g} is beyond the end of '
                           f'{bag}, which lasts {duration_s:.3f} s: give an offset in '
                           f'[0, {duration_s:.3f}]')
    recorded = sorted({m.topic for m in messages})
    missing = sorted(set(topics or ()) - set(recorded))
    if missing:
        raise StartupError(f'parameter topics: {", ".join(missing)} not in {bag}; its topics: '
                           f'{", ".join(recorded)}')


def played_line(count: int) -> str:
    """The player's last line of output."""
    return f'played {count} messages'


def progress_line(played: int, total: int, bag_time_s: float, bag_span_s: float) -> str:
    """A progress line while playing: messages of this pass played (made-up /clock ticks not
    counted) and the bag time reached, from the bag's first message."""
    return (f'progress: played {played} of {total} messages, bag time {bag_time_s:.1f} of '
            f'{bag_span_s:.1f} s')



class PlayerNode(Node):
    """Republishes a bag.

    Parameters
    ----------
    **node_kwargs
        Passed to ``rclpy.node.Node``.

    Attributes
    ----------
    plan : list of PlaybackItem
        One pass over the bag.
    played : int
        Messages published so far, made-up /clock ticks not counted.

    Raises
    ------
    sphere_twin.bag.reader.BagError
        If the bag cannot be read.
    ValueError
        For a bad parameter.
    """

    def __init__(self, **node_kwargs: Any) -> None:
        super().__init__('player', **node_kwargs)
        p = self._declare_parameters()
        if not p['bag']:
            raise ValueError('parameter bag (the bag directory to play) is required')
        located = locate_bag(p['bag'])
        if located.note:
            self.get_logger().info(located.note)
        self.bag = str(located.directory)
        self.loop = p['loop']
        self.wait_for_subscribers_s = p['wait_for_subscribers_s']
        self.delay_s = p['delay_s']
        metadata = read_metadata(self.bag)
        listed = {t['topic_metadata']['name']: t['topic_metadata']
                  for t in metadata.get('topics_with_message_count') or []}
        topics = [t for t in (p['topics'] or []) if t] or None
        messages = [in_current_contract(m) for m in read_messages(self.bag)]
        check_selection(self.bag, messages, p['start_offset_s'], topics)
        types = {m.topic: m.type_name for m in messages}
        self.plan = playback_plan(messages, p['rate'], p['start_offset_s'], topics,
                                  p['publish_clock'])
        self._bag_start_ns = messages[0].log_time_ns if messages else 0
        self._bag_span_s = ((messages[-1].log_time_ns - self._bag_start_ns) / NS_PER_S
                            if messages else 0.0)
        self._messages_per_pass = sum(item.data is not None for item in self.plan)
        contract = {t.name: t for t in ALL_TOPICS}
        self._playback_publishers: dict[str, Any] = {}
        for item in self.plan:
            if item.topic in self._playback_publishers:
                continue
            type_name = types.get(item.topic, bag_format.type_name_of(CLOCK.msg_type))
            try:
                msg_type = message_class(type_name)
            except (ImportError, AttributeError, ValueError):
                raise ValueError(f'message type {type_name} of {item.topic} is not '
                                 'installed') from None
            qos = (contract[item.topic].qos.to_profile() if item.topic in contract
                   else recorded_qos(listed.get(item.topic, {})))
            self._playback_publishers[item.topic] = self.create_publisher(msg_type, item.topic, qos)
        self._clock_type = CLOCK.msg_type
        self.played = 0
        self.get_logger().info(
            f'domain id {self.context.get_domain_id()}; playing {len(self.plan)} publications '
            f'on {len(self._playback_publishers)} topics from {self.bag} at rate {p["rate"]:g}')

    def _declare_parameters(self) -> dict[str, Any]:
        return declare_node_parameters(self, PLAYER_PARAMETERS)

    def publish_item(self, item: PlaybackItem) -> None:
        """Publish one :class:`PlaybackItem` (the recorded bytes, or a made-up /clock tick)."""
        publisher = self._playback_publishers[item.topic]
        if item.data is None:
            msg = self._clock_type()
            msg.clock.sec, msg.clock.nanosec = divmod(item.log_time_ns, NS_PER_S)
            publisher.publish(msg)
        else:
            publisher.publish(bytes(item.data))
            self.played += 1

    def wait_for_subscribers(self) -> bool:
        """Wait up to ``wait_for_subscribers_s`` until every publisher has a subscriber."""
        deadline = time.monotonic() + self.wait_for_subscribers_s
        while time.monotonic() < deadline and self.context.ok():
            if all(p.get_subscription_count() > 0 for p in self._playback_publishers.values()):
                return True
            time.sleep(0.02)
        return all(p.get_subscription_count() > 0 for p in self._playback_publishers.values())

    def _sleep(self, duration_s: float) -> None:
        deadline = time.monotonic() + duration_s
        while self.context.ok() and time.monotonic() < deadline:
            time.sleep(max(0.0, min(deadline - time.monotonic(), SLEEP_SLICE_S)))

    def play_once(self) -> None:
        """Publish :attr:`plan` at its times, logging a progress line every
        PROGRESS_PERIOD_S of wall time."""
        start = time.monotonic()
        played_before = self.played
        next_progress_s = start + PROGRESS_PERIOD_S
        for item in self.plan:
            while self.context.ok():
                remaining = start + item.due_s - time.monotonic()
                if remaining <= 0:
                    break
                time.sleep(min(remaining, SLEEP_SLICE_S))
            if not self.context.ok():
                return
            self.publish_item(item)
            if time.monotonic() >= next_progress_s:
                self.get_logger().info(progress_line(
                    self.played - played_before, self._messages_per_pass,
                    (item.log_time_ns - self._bag_start_ns) / NS_PER_S, self._bag_span_s))
                next_progress_s = time.monotonic() + PROGRESS_PERIOD_S

    def play(self) -> None:
        """Play the bag (for ever with ``loop``), then wait for acknowledgements."""
        if self.wait_for_subscribers_s > 0 and not self.wait_for_subscribers():
            missing = [t for t, p in self._playback_publishers.items()
                       if p.get_subscription_count() == 0]
            self.get_logger().warning(f'playing without subscribers on {", ".join(missing)}')
        self._sleep(self.delay_s)
        while self.context.ok():
            self.play_once()
            if not self.loop:
                break
        for publisher in self._playback_publishers.values():
            publisher.wait_for_all_acked(Duration(seconds=ACK_TIMEOUT_S))

    def summary(self) -> str:
        return played_line(self.played)


def main(args: list[str] | None = None) -> int:
    """Play a bag; exit status 2, with one line, if it cannot be read or a parameter is bad."""
    return run_node(PlayerNode, args, spin=PlayerNode.play, farewell=PlayerNode.summary,
                    name='player',
                    parameters=PLAYER_PARAMETERS)


if __name__ == '__main__':
    sys.exit(main())
