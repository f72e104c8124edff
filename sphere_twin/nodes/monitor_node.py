"""The monitor node: counts surface-normal messages and reports once a second.

On exit, by a signal or after ``max_messages``, it prints the line
``received N messages on /sphere/surface_normal`` to standard output, which the demo and
the tests read (see :mod:`sphere_twin.monitor_summary`).
"""

import sys
from typing import Any

import numpy as np
import rclpy
from numpy.typing import NDArray
from rclpy.node import Node
from rclpy.task import Future

from msg_defs.conversions import surface_normal_from_msg
from msg_defs.topics import SURFACE_NORMAL
from sphere_twin.monitor_summary import summary_line
from sphere_twin.node_runtime.parameter_specs import declare_node_parameters
from sphere_twin.node_runtime.ros_env import run_node
from sphere_twin.nodes.parameters import MONITOR_PARAMETERS

REPORT_PERIOD_S = 1.0


class MonitorNode(Node):
    """Counts messages on ``/sphere/surface_normal``.

    Attributes
    ----------
    count : int
        Messages received so far (valid or not); stops growing once ``max_messages`` is hit.
    invalid_count : int
        How many of them broke the contract (logged as warnings).
    done : rclpy.task.Future
        Completes with the count when ``max_messages`` (> 0) messages have arrived.
    """

    def __init__(self, **node_kwargs: Any) -> None:
        super().__init__('monitor', **node_kwargs)
        declare_node_parameters(self, MONITOR_PARAMETERS)
        self.max_messages = self.get_parameter('max_messages').value
        self.count = 0
        self.invalid_count = 0
        self.latest_normal: NDArray[np.float64] | None = None
        self.done = Future()
        self._count_at_last_report = 0
        self.create_subscription(
            SURFACE_NORMAL.msg_type, SURFACE_NORMAL.name, self.on_message,
            SURFACE_NORMAL.qos.to_profile())
        self.create_timer(REPORT_PERIOD_S, self.on_report_timer)

    def on_message(self, msg: Any) -> None:
        """Count one message; complete :attr:`done` at ``max_messages``."""
        if self.done.done():
            return
        self.count += 1
        try:
            self.latest_normal = surface_normal_from_msg(msg)
        except ValueError as error:
            self.invalid_count += 1
            self.get_logger().warning(f'invalid message on {SURFACE_NORMAL.name}: {error}')
        if self.max_messages and self.count >= self.max_messages:
            self.done.set_result(self.count)

    def on_report_timer(self) -> None:
        """Log the count, the rate over the last period and the latest normal."""
        rate_hz = (self.count - self._count_at_last_report) / REPORT_PERIOD_S
        self._count_at_last_report = self.count
        latest = ('none yet' if self.latest_normal is None
                  else np.array2string(self.latest_normal, precision=4))
        self.get_logger().info(
            f'{self.count} messages on {SURFACE_NORMAL.name} ({rate_hz:g} Hz), '
            f'latest normal {latest}')

    def summary(self) -> str:
        """The final line, ``received N messages on /sphere/surface_normal``."""
        return summary_line(self.count, SURFACE_NORMAL.name)


def main(args: list[str] | None = None) -> int:
    # Never completes when max_messages is 0, so the node then runs until signalled.
    return run_node(MonitorNode, args,
                    spin=lambda node: rclpy.spin_until_future_complete(node, node.done),
                    farewell=MonitorNode.summary, name='monitor',
                    parameters=MONITOR_PARAMETERS)


if __name__ == '__main__':
    sys.exit(main())
