"""The node executables of ``setup.py`` (``ros2 run sphere_twin simulator``, ``ros2 launch``).

Each takes SIGINT and SIGTERM as a clean shutdown before it imports its node's module, which
takes up to seconds (:func:`~sphere_twin.node_runtime.ros_env.run_node_module`), so a Ctrl-C
in a node's first second ends it with status 0 and no traceback. Nothing here imports rclpy.
"""

from sphere_twin.node_runtime.ros_env import run_node_module


def simulator() -> int:
    return run_node_module('sphere_twin.nodes.simulator_node')


def controller() -> int:
    return run_node_module('sphere_twin.nodes.controller_node')


def reference() -> int:
    return run_node_module('sphere_twin.nodes.reference_node')


def recorder() -> int:
    return run_node_module('sphere_twin.nodes.recorder_node')


def player() -> int:
    return run_node_module('sphere_twin.nodes.player_node')


def monitor() -> int:
    return run_node_module('sphere_twin.nodes.monitor_node')
