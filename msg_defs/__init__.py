"""The message contract shared by every node: topic names, types, QoS, frames, units.

:mod:`msg_defs.topics` says what travels on which topic, :mod:`msg_defs.conversions` turns
messages into numpy arrays and back (validating on the way in), and :mod:`msg_defs.ros_env`
holds the environment and signal hygiene every executable applies before starting ROS.
Nothing here imports rclpy at import time, so tools that never join a ROS graph can use it.
"""
