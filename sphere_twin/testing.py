"""The twin as a test fixture for other packages: a lockstep simulator on a private domain.

``lockstep_twin()`` starts the simulator node in its own process, in lockstep mode, on a ROS
domain of its own with discovery limited to localhost, and hands back a :class:`TwinClient`
that joins the same domain from the test's process. In lockstep the simulator advances time
only while a command is in effect, so a test sees the same samples however slow the machine.

Examples
--------
In a ``conftest.py``::

    import pytest
    from sphere_twin.testing import lockstep_twin

    @pytest.fixture
    def twin():
        with lockstep_twin(plant='discrete', seed=1) as client:
            yield client

and in a test::

    def test_my_controller_moves_the_mirror(twin):
        start = twin.wait_for_normal()
        settled = twin.kick(action=0, intensity=1.0)
        assert settled[0] > start[0]
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from typing import TYPE_CHECKING, Any

from msg_defs.device import NS_PER_S
from sphere_twin.node_runtime.ros_env import ensure_localhost_discovery
from sphere_twin.processes import NodeProcess, fresh_domain_id, parameter_args, running_nodes

if TYPE_CHECKING:
    import numpy as np
    from numpy.typing import ArrayLike, NDArray

    from msg_defs.topics import Topic
    from sphere_sim.kicks.lookup_table import CombinedKickPlant, LookupTable

DEFAULT_TIMEOUT_S = 30.0
SPIN_PERIOD_S = 0.02
RECORD_DEPTH = 1000  # messages a probe keeps per topic between two spins


class TwinTimeoutError(TimeoutError):
    """The simulator did not answer in time."""


def _sample_of(msg: Any) -> tuple[float, NDArray[np.float64]]:
    from msg_defs.conversions import ns_from_time, surface_normal_from_msg

    return ns_from_time(msg.header.stamp) / NS_PER_S, surface_normal_from_msg(msg)


class TopicProbe:
    """A node in the test's own process on a given domain: records topics, publishes.

    Parameters
    ----------
    domain_id : int
    topics : sequence of msg_defs.topics.Topic
        Topics to record; their messages collect in ``messages[topic.name]``.
    process : sphere_twin.processes.NodeProcess, optional
        A node process to watch: waiting fails early if it exits.
    """

    def __init__(self, domain_id: int, topics: Iterable[Topic] = (),
                 process: NodeProcess | None = None) -> None:
        import rclpy
        from rclpy.executors import SingleThreadedExecutor

        self.domain_id = domain_id
        self.process = process
        self.messages: dict[str, list[Any]] = {topic.name: [] for topic in topics}
        self._context = rclpy.Context()
        rclpy.init(context=self._context, domain_id=domain_id)
        self.node = rclpy.create_node('twin_test_probe', context=self._context)
        self._executor = SingleThreadedExecutor(context=self._context)
        self._executor.add_node(self.node)
        self._publishers: dict[str, Any] = {}
        for topic in topics:
            # A deep history: while the test publishes a burst it takes nothing, and the
            # topic's own depth would let DDS overwrite what the test then looks for.
            self.node.create_subscription(topic.msg_type, topic.name,
                                          self.messages[topic.name].append,
                                          topic.qos.to_profile(min_depth=RECORD_DEPTH))

    def publisher(self, topic: Topic) -> Any:
        """The probe's publisher on ``topic`` (created once)."""
        if topic.name not in self._publishers:
            self._publishers[topic.name] = self.node.create_publisher(
                topic.msg_type, topic.name, topic.qos.to_profile())
        return self._publishers[topic.name]

    def close(self) -> None:
        import rclpy

        self._executor.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self._context)

    def spin_until(self, condition: Callable[[], object], timeout_s: float = DEFAULT_TIMEOUT_S,
                   what: str = 'a condition') -> None:
        """Process messages until ``condition()`` holds; TwinTimeoutError after ``timeout_s``."""
        deadline = time.monotonic() + timeout_s
        while not condition():
            if time.monotonic() > deadline:
                output = '' if self.process is None else self.process.stderr_text()[-2000:]
                raise TwinTimeoutError(f'no {what} within {timeout_s} s\n{output}')
            if self.process is not None and not self.process.running():
                raise TwinTimeoutError(f'the node process exited with '
                                       f'{self.process.returncode}')
            self._executor.spin_once(timeout_sec=SPIN_PERIOD_S)

    def spin_once(self, timeout_s: float = 0.0) -> None:
        """Process the messages that are there, waiting up to ``timeout_s`` for one."""
        self._executor.spin_once(timeout_sec=timeout_s)

    def wait_for_graph(self, topic: Topic, publishers: int = 0, subscribers: int = 0,
                       timeout_s: float = DEFAULT_TIMEOUT_S) -> None:
        """Until the probe sees at least that many publishers and subscribers on ``topic``
        (its own endpoints on it, if any, count too)."""
        node = self.node
        self.spin_until(lambda: node.count_publishers(topic.name) >= publishers
                        and node.count_subscribers(topic.name) >= subscribers, timeout_s,
                        f'{publishers} publisher(s) and {subscribers} subscriber(s) on '
                        f'{topic.name}')

    def wait_for_subscribers(self, topic: Topic, timeout_s: float = DEFAULT_TIMEOUT_S) -> None:
        """Until someone subscribes to ``topic`` (discovery is asynchronous)."""
        publisher = self.publisher(topic)
        self.spin_until(lambda: publisher.get_subscription_count() > 0, timeout_s,
                        f'subscriber on {topic.name}')


class TwinClient(TopicProbe):
    """A test's handle on a running simulator: send commands, read samples.

    Parameters
    ----------
    process : sphere_twin.processes.NodeProcess
    domain_id : int
    kicks : sphere_sim.kicks.lookup_table.LookupTable or CombinedKickPlant
        The kicks :meth:`kick` sends (their programmes).
    window_s : float
        Kick period: the plant's kick is over this long after its start (the settled sample
        is the first at or after it).

    Attributes
    ----------
    samples : list of (time_s, normal)
        Every measured surface normal received, in order.
    diagnostics : list of str
        Messages of every ``/diagnostics`` status received.
    rejections : list of str
        Those of them that report a rejected command (not the periodic status).
    """

    def __init__(self, process: NodeProcess, domain_id: int,
                 kicks: LookupTable | CombinedKickPlant, window_s: float) -> None:
        from msg_defs.topics import DIAGNOSTICS, SURFACE_NORMAL

        super().__init__(domain_id, (SURFACE_NORMAL, DIAGNOSTICS), process)
        self.kicks = kicks
        self.window_s = window_s
        self._normals = self.messages[SURFACE_NORMAL.name]
        self._diagnostics = self.messages[DIAGNOSTICS.name]

    @property
    def samples(self) -> list[tuple[float, NDArray[np.float64]]]:
        return [_sample_of(m) for m in self._normals]

    def latest_sample(self) -> tuple[float, NDArray[np.float64]]:
        """(time_s, normal) of the last sample received."""
        return _sample_of(self._normals[-1])

    @property
    def diagnostics(self) -> list[str]:
        return [status.message for m in self._diagnostics for status in m.status]

    @property
    def rejections(self) -> list[str]:
        from diagnostic_msgs.msg import DiagnosticStatus

        return [status.message for m in self._diagnostics for status in m.status
                if status.level != DiagnosticStatus.OK]

    def status(self) -> dict[str, str]:
        """The key-values of the last ``/diagnostics`` status received, or {} before one."""
        if not self._diagnostics:
            return {}
        from msg_defs.conversions import status_values

        return status_values(self._diagnostics[-1].status[0])

    def wait_for_normal(self, timeout_s: float = DEFAULT_TIMEOUT_S) -> NDArray[np.float64]:
        """The latest measured normal, waiting for the first one."""
        self.spin_until(lambda: self._normals, timeout_s, 'surface normal')
        return self.latest_sample()[1]

    def send_programme(self, times_s: ArrayLike, voltages_v: Iterable[ArrayLike]) -> None:
        """Publish a pulse programme (segments from now)."""
        from msg_defs.conversions import programme_to_msg
        from msg_defs.topics import PULSE_PROGRAM

        self.send_raw(PULSE_PROGRAM, programme_to_msg(times_s, voltages_v))

    def send_voltages(self, voltages_v: ArrayLike) -> None:
        from msg_defs.conversions import voltages_to_msg
        from msg_defs.topics import VOLTAGE_COMMAND

        self.send_raw(VOLTAGE_COMMAND, voltages_to_msg(voltages_v))

    def send_raw(self, topic: Topic, msg: Any) -> None:
        """Publish any message on a topic of the contract (also for tests of bad input)."""
        self.wait_for_subscribers(topic)
        self.publisher(topic).publish(msg)

    def kick(self, action: int, intensity: float,
             timeout_s: float = DEFAULT_TIMEOUT_S) -> NDArray[np.float64]:
        """Send the design's kick ``action`` at ``intensity``; returns the settled normal.

        The settled sample is the first one at or after the kick window's end; in lockstep
        nothing comes after it until the next command.
        """
        self.wait_for_normal()
        start_s, normal = self.latest_sample()
        programme = self.kicks.programme(action, intensity, normal)
        self.send_programme(*programme.segments())
        window_s = max(programme.duration_s, self.window_s)
        self.spin_until(lambda: self.latest_sample()[0] >= start_s + window_s - 1e-9,
                        timeout_s, 'settled sample after the kick')
        return self.latest_sample()[1]


@contextlib.contextmanager
def lockstep_twin(plant: str = 'discrete', scene: str = 'rest', seed: int = 0,
                  noise_std_rad: float = 0.0, publish_rate_hz: float | None = None,
                  tables: Sequence[str] = (), domain_id: int | None = None,
                  extra_parameters: Mapping[str, object] | None = None,
                  ) -> Iterator[TwinClient]:
    """Start a lockstep simulator on a private domain; yield a :class:`TwinClient`.

    Parameters
    ----------
    plant : str
        ``discrete`` (the shipped kick table) or ``continuous``.
    scene : str
    seed : int
    noise_std_rad : float
    publish_rate_hz : float, optional
        The simulator's default (the sensor's rate) unless given.
    tables : sequence of str
        Kick tables of the discrete plant (and of :meth:`TwinClient.kick`); the shipped
        default if empty.
    domain_id : int, optional
        A fresh one by default.
    extra_parameters : dict, optional
        More simulator parameters.
    """
    from sphere_sim.kicks.discrete import kick_period_s
    from sphere_sim.kicks.lookup_table import load_kick_model

    ensure_localhost_discovery()
    domain_id = fresh_domain_id() if domain_id is None else domain_id
    params = dict(plant=plant, scene=scene, seed=seed, noise_std_rad=float(noise_std_rad),
                  lockstep=True, tables=list(tables) or [''], **(extra_parameters or {}))
    if publish_rate_hz is not None:
        params['publish_rate_hz'] = float(publish_rate_hz)
    kicks = load_kick_model(tables)
    with running_nodes(domain_id=domain_id) as group:
        process = group.start('simulator', parameter_args(**params))
        client = TwinClient(process, domain_id, kicks, kick_period_s(kicks))
        try:
            yield client
        finally:
            client.close()

