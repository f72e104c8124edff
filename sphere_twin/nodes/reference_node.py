"""The reference node: a setpoint, then optionally the trajectory of eq. (64), on /sphere/reference.

Time is the node's clock, so with ``use_sim_time`` it follows the simulator's ``/clock``. A
reference beyond the reachable cone is clamped to its edge with a warning.
"""

from __future__ import annotations

import sys
from typing import TYPE_CHECKING, Any

from rclpy.node import Node

from msg_defs.conversions import surface_normal_to_msg
from msg_defs.device import NS_PER_S
from msg_defs.markers import reference_markers
from msg_defs.topics import CLOCK, MARKERS, SPHERE_REFERENCE
from sphere_control.reference import CircleTrajectory, ScheduledReference, Setpoint, sample
from sphere_twin.node_runtime.pace import PaceMeter
from sphere_twin.node_runtime.parameter_specs import (
    accept_parameter_changes,
    declare_node_parameters,
)
from sphere_twin.node_runtime.ros_env import run_node
from sphere_twin.nodes.parameters import REFERENCE_PARAMETERS

if TYPE_CHECKING:
    from sphere_control.reference import ReferenceSample


class ReferenceNode(Node):
    """Publishes the reference normal at a fixed rate."""

    def __init__(self, **node_kwargs: Any) -> None:
        super().__init__('reference', **node_kwargs)
        p = declare_node_parameters(self, REFERENCE_PARAMETERS)
        x, y = p['setpoint_xy']
        self.schedule = ScheduledReference(Setpoint((x, y)),
                                           CircleTrajectory(p['amplitude'], p['frequency_hz']),
                                           p['trajectory_start_s'], p['trajectory_offset_s'])
        self._publisher = self.create_publisher(
            SPHERE_REFERENCE.msg_type, SPHERE_REFERENCE.name, SPHERE_REFERENCE.qos.to_profile())
        self._marker_publisher = self.create_publisher(MARKERS.msg_type, MARKERS.name,
                                                       MARKERS.qos.to_profile())
        self._start_ns: int | None = None
        self._warned_clamp = False
        self._clock_checked = False
        self.pace = PaceMeter()
        self._timer = self.create_timer(1.0 / p['publish_rate_hz'], self.on_timer)
        accept_parameter_changes(self, REFERENCE_PARAMETERS, self._parameter_changed)
        # Latched at once: with use_sim_time the timer waits for /clock, and a controller
        # should hold the reference before the simulator starts. Created at simulated time 0,
        # before any /clock, the timer still fires once /clock passes its period (rcl checks
        # a ROS-time timer on every jump of the clock), so the reference follows /clock as
        # soon as it hears it; one that never hears it holds its setpoint (test_clock_wait).
        self.on_timer()

    def _parameter_changed(self, name: str, value: Any) -> None:
        """Take a ``ros2 param set`` of the publish rate (the one settable parameter)."""
        self.destroy_timer(self._timer)
        self._timer = self.create_timer(1.0 / value, self.on_timer)
        self.get_logger().info(f'{name} set to {value:g}')

    def reference_at(self, elapsed_s: float) -> tuple[ReferenceSample, str]:
        """(sample, phase name) at ``elapsed_s`` since the first publication."""
        return sample(self.schedule, elapsed_s), self.schedule.phase_at(elapsed_s)

    def on_timer(self) -> None:
        now = self.get_clock().now()
        if self._start_ns is None:
            self._start_ns = now.nanoseconds
        elapsed_s = (now.nanoseconds - self._start_ns) / NS_PER_S
        if elapsed_s > 0.0:  # not the latched first one, published before time runs
            self.pace.note(elapsed_s)
        reference, _ = self.reference_at(elapsed_s)
        if reference.clamped and not self._warned_clamp:
            requested = reference.requested_xy
            self.get_logger().warning(
                f'reference ({requested[0]:.4f}, {requested[1]:.4f}) lies outside the '
                f'reachable cone; clamped to its edge')
        self._warned_clamp = reference.clamped
        self._publisher.publish(surface_normal_to_msg(reference.normal, now.to_msg()))
        self._marker_publisher.publish(reference_markers(reference.normal, now.to_msg()))
        self._check_clock()

    def _check_clock(self) -> None:
        """Warn once when a simulator publishes /clock but this node stamps wall time: every
        stamp of the twin is simulated time, so the reference should follow /clock."""
        if self._clock_checked or self.get_parameter('use_sim_time').value:
            return
        if self.count_publishers(CLOCK.name) > 0:
            self._clock_checked = True
            self.get_logger().warning(
                f'{CLOCK.name} is published (a simulator runs) but this node stamps wall time: '
                'start it with use_sim_time:=true so its stamps are simulated time')

    def summary(self) -> str:
        switch_s = self.schedule.switch_s
        return (f'reference: setpoint {self.schedule.setpoint.xy}, trajectory from '
                + (f'{switch_s:g} s' if switch_s >= 0 else 'never')
                + f'; real-time factor {self.pace.real_time_factor():.3f}')


def main(args: list[str] | None = None) -> int:
    return run_node(ReferenceNode, args, farewell=ReferenceNode.summary, name='reference',
                    parameters=REFERENCE_PARAMETERS)


if __name__ == '__main__':
    sys.exit(main())

