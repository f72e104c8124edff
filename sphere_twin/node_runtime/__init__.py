"""How every executable joins and leaves the ROS graph: discovery kept on this machine, SIGINT
and SIGTERM as a clean shutdown, the shared ``main()`` of the nodes, parameter descriptors, the
real-time factor a node saw.

The lowest package beside :mod:`msg_defs`: it imports none of the project's packages, and
rclpy only inside the functions that start a node, so the CLI and the tests can use its
environment hygiene without ROS.
"""
