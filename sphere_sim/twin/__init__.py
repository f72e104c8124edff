"""The twin behind the device's topics: the plants, their clock and command queue, the node.

Only :mod:`~sphere_sim.twin.simulator_node` imports rclpy; the rest is plain Python that the
tests drive directly. May import every other room of :mod:`sphere_sim` and :mod:`msg_defs`.
"""
