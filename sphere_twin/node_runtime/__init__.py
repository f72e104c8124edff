"""How every executable joins and leaves the ROS graph: discovery kept on this machine, SIGINT
and SIGTERM as a clean shutdown, the shared ``main()`` of the nodes (``ros_env``), a node's
parameters declared and checked from their specs (``parameter_specs``), the publishing thread
(``outbox``) and the real-time factor a node saw (``pace``).

It imports no other part of the project, and rclpy only inside the functions that start a
node or declare its parameters, so the CLI and the tests can use it without ROS.
"""
