"""The simulator node: steps a plant at a fixed rate and publishes the mirror's surface normal.

Subscribes to ``/beams/voltage_command`` and holds the last valid command on the beams; a
command that breaks the contract is logged and dropped, the previous one stays in force.
"""

import os

import numpy as np
import rclpy
from rcl_interfaces.msg import FloatingPointRange, ParameterDescriptor
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node

from msg_defs.conversions import surface_normal_to_msg, voltages_from_msg
from msg_defs.ros_env import (
    DISCOVERY_RANGE_VAR,
    ensure_localhost_discovery,
    install_shutdown_signal_handlers,
)
from msg_defs.topics import BEAM_COUNT, SURFACE_NORMAL, VOLTAGE_COMMAND
from sphere_sim.plants import RestingPlant

DEFAULT_PUBLISH_RATE_HZ = 50.0
MAX_PUBLISH_RATE_HZ = 1000.0


class SimulatorNode(Node):
    """Runs a :class:`sphere_sim.plants.Plant` and publishes its surface normal.

    Each timer tick advances the plant by one period under the voltages in force and
    publishes the resulting normal, so simulated time advances by ``1/publish_rate_hz`` per
    message.

    Parameters
    ----------
    plant : sphere_sim.plants.Plant, optional
        The plant to run; a :class:`~sphere_sim.plants.RestingPlant` by default.
    **node_kwargs
        Passed to ``rclpy.node.Node`` (e.g. ``context``).
    """

    def __init__(self, plant=None, **node_kwargs):
        super().__init__('simulator', **node_kwargs)
        self.declare_parameter(
            'publish_rate_hz', DEFAULT_PUBLISH_RATE_HZ,
            ParameterDescriptor(
                description='Rate at which the plant is stepped and the normal published (Hz).',
                floating_point_range=[FloatingPointRange(
                    from_value=1.0, to_value=MAX_PUBLISH_RATE_HZ, step=0.0)],
                read_only=True,
            ))
        self.publish_rate_hz = self.get_parameter('publish_rate_hz').value
        self.period_s = 1.0 / self.publish_rate_hz
        self.plant = RestingPlant() if plant is None else plant
        self.voltages_v = np.zeros(BEAM_COUNT)

        self._normal_publisher = self.create_publisher(
            SURFACE_NORMAL.msg_type, SURFACE_NORMAL.name, SURFACE_NORMAL.qos.to_profile())
        self.create_subscription(
            VOLTAGE_COMMAND.msg_type, VOLTAGE_COMMAND.name, self.on_voltage_command,
            VOLTAGE_COMMAND.qos.to_profile())
        self.create_timer(self.period_s, self.on_timer)
        self.get_logger().info(
            f'{DISCOVERY_RANGE_VAR}={os.environ.get(DISCOVERY_RANGE_VAR, "(unset)")}, '
            f'domain id {self.context.get_domain_id()}; publishing {SURFACE_NORMAL.name} at '
            f'{self.publish_rate_hz:g} Hz')

    def on_voltage_command(self, msg):
        """Hold a valid command on the beams; log and drop an invalid one."""
        try:
            self.voltages_v = voltages_from_msg(msg)
        except ValueError as error:
            self.get_logger().error(f'dropped {VOLTAGE_COMMAND.name}: {error}')

    def on_timer(self):
        """Advance the plant by one period and publish the surface normal."""
        normal = self.plant.step(self.period_s, self.voltages_v)
        self._normal_publisher.publish(
            surface_normal_to_msg(normal, stamp=self.get_clock().now().to_msg()))


def main(args=None):
    ensure_localhost_discovery()
    install_shutdown_signal_handlers()
    rclpy.init(args=args)
    node = None
    try:
        # Constructed inside the try: a signal during start-up is a clean shutdown too.
        node = SimulatorNode()
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()


if __name__ == '__main__':
    main()
