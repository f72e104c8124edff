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

import contextlib
import time

from msg_defs.ros_env import ensure_localhost_discovery
from sphere_twin.processes import fresh_domain_id, parameter_args, running_nodes

DEFAULT_TIMEOUT_S = 30.0
SPIN_PERIOD_S = 0.02


class TwinTimeoutError(TimeoutError):
    """The simulator did not answer in time."""


class TwinClient:
    """A test's handle on a running simulator: send commands, read samples.

    Parameters
    ----------
    process : sphere_twin.processes.NodeProcess
    domain_id : int
    design : sphere_sim.kicks.KickDesign
        The design whose kicks :meth:`kick` sends.
    window_s : float
        Kick window: the settled sample comes this long after the kick's start.

    Attributes
    ----------
    process : sphere_twin.processes.NodeProcess
    domain_id : int
    samples : list of (time_s, normal)
        Every measured surface normal received, in order.
    diagnostics : list of str
        Messages of every ``/diagnostics`` status received.
    """

    def __init__(self, process, domain_id, design, window_s):
        import rclpy
        from rclpy.executors import SingleThreadedExecutor

        from msg_defs.conversions import ns_from_time, surface_normal_from_msg
        from msg_defs.topics import DIAGNOSTICS, PULSE_PROGRAM, SURFACE_NORMAL, VOLTAGE_COMMAND

        self.process = process
        self.domain_id = domain_id
        self.design = design
        self.window_s = window_s
        self.samples = []
        self.diagnostics = []
        self._context = rclpy.Context()
        rclpy.init(context=self._context, domain_id=domain_id)
        self._node = rclpy.create_node('twin_test_client', context=self._context)
        self._executor = SingleThreadedExecutor(context=self._context)
        self._executor.add_node(self._node)

        def on_normal(msg):
            self.samples.append((ns_from_time(msg.header.stamp) * 1e-9,
                                 surface_normal_from_msg(msg)))

        def on_diagnostics(msg):
            self.diagnostics.extend(status.message for status in msg.status)

        self._node.create_subscription(SURFACE_NORMAL.msg_type, SURFACE_NORMAL.name, on_normal,
                                       SURFACE_NORMAL.qos.to_profile())
        self._node.create_subscription(DIAGNOSTICS.msg_type, DIAGNOSTICS.name, on_diagnostics,
                                       DIAGNOSTICS.qos.to_profile())
        self._programme_pub = self._node.create_publisher(
            PULSE_PROGRAM.msg_type, PULSE_PROGRAM.name, PULSE_PROGRAM.qos.to_profile())
        self._voltage_pub = self._node.create_publisher(
            VOLTAGE_COMMAND.msg_type, VOLTAGE_COMMAND.name, VOLTAGE_COMMAND.qos.to_profile())

    def close(self):
        import rclpy

        self._executor.shutdown()
        self._node.destroy_node()
        rclpy.try_shutdown(context=self._context)

    def spin_until(self, condition, timeout_s=DEFAULT_TIMEOUT_S, what='a condition'):
        """Process messages until ``condition()`` holds; TwinTimeoutError after ``timeout_s``."""
        deadline = time.monotonic() + timeout_s
        while not condition():
            if time.monotonic() > deadline:
                raise TwinTimeoutError(f'no {what} within {timeout_s} s; simulator output:\n'
                                  f'{self.process.stderr_text()[-2000:]}')
            if not self.process.running:
                raise TwinTimeoutError(f'the simulator exited with {self.process.returncode}')
            self._executor.spin_once(timeout_sec=SPIN_PERIOD_S)

    def wait_for_normal(self, timeout_s=DEFAULT_TIMEOUT_S):
        """The latest measured normal, waiting for the first one."""
        self.spin_until(lambda: self.samples, timeout_s, 'surface normal')
        return self.samples[-1][1]

    def wait_for_subscribers(self, timeout_s=DEFAULT_TIMEOUT_S):
        """Until the simulator subscribes to the command topics (discovery is asynchronous)."""
        self.spin_until(lambda: self._programme_pub.get_subscription_count() > 0
                        and self._voltage_pub.get_subscription_count() > 0,
                        timeout_s, 'simulator subscription')

    def send_programme(self, times_s, voltages_v):
        """Publish a pulse programme (segments from now)."""
        from msg_defs.conversions import programme_to_msg

        self.wait_for_subscribers()
        self._programme_pub.publish(programme_to_msg(times_s, voltages_v))

    def send_voltages(self, voltages_v):
        from msg_defs.conversions import voltages_to_msg

        self.wait_for_subscribers()
        self._voltage_pub.publish(voltages_to_msg(voltages_v))

    def send_raw(self, topic_name, msg):
        """Publish any message on a command topic (for tests of bad input)."""
        self.wait_for_subscribers()
        publisher = {self._programme_pub.topic_name: self._programme_pub,
                     self._voltage_pub.topic_name: self._voltage_pub}[topic_name]
        publisher.publish(msg)

    def kick(self, action, intensity, timeout_s=DEFAULT_TIMEOUT_S):
        """Send the design's kick ``action`` at ``intensity``; returns the settled normal.

        The settled sample is the first one at or after the kick window's end; in lockstep
        nothing comes after it until the next command.
        """
        from sphere_sim.plants import kick_programmes

        self.wait_for_normal()
        start_s = self.samples[-1][0]
        programme = kick_programmes(self.design, intensity)[action]
        self.send_programme(*programme.segments())
        window_s = max(programme.duration_s, self.window_s)
        self.spin_until(lambda: self.samples[-1][0] >= start_s + window_s - 1e-9, timeout_s,
                        'settled sample after the kick')
        return self.samples[-1][1]


@contextlib.contextmanager
def lockstep_twin(plant='discrete', scene='rest', seed=0, noise_std_rad=0.0,
                  publish_rate_hz=50.0, domain_id=None, extra_parameters=None):
    """Start a lockstep simulator on a private domain; yield a :class:`TwinClient`.

    Parameters
    ----------
    plant : str
        ``discrete`` (the shipped kick table) or ``continuous``.
    scene : str
    seed : int
    noise_std_rad : float
    publish_rate_hz : float
    domain_id : int, optional
        A fresh one by default.
    extra_parameters : dict, optional
        More simulator parameters.
    """
    from sphere_sim.lookup_table import LookupTable

    ensure_localhost_discovery()
    domain_id = fresh_domain_id() if domain_id is None else domain_id
    params = dict(plant=plant, scene=scene, seed=seed, noise_std_rad=float(noise_std_rad),
                  publish_rate_hz=float(publish_rate_hz), lockstep=True,
                  **(extra_parameters or {}))
    table = LookupTable.load_current()
    with running_nodes(domain_id=domain_id) as group:
        process = group.start('simulator', parameter_args(**params))
        client = TwinClient(process, domain_id, table.spec.design, table.spec.window_s)
        try:
            yield client
        finally:
            client.close()

