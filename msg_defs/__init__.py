"""The message contract shared by every node: topic names, types, QoS, frames, units.

:mod:`msg_defs.device` holds the device's constants and the project's defaults (ROS-free; the
contract re-exports them), :mod:`msg_defs.topics` says what travels on which topic, and
:mod:`msg_defs.conversions` turns messages into numpy arrays and back (validating on the way
in). Nothing here imports rclpy at import time, so tools that never join a ROS graph can use it.
"""
