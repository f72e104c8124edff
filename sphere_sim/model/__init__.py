"""The physical model of §3: parameter sets, scenes, the parts, and their assembly.

Holds what the device is (parameters, geometry, electrostatics, contact, friction), the compiled
right-hand side and Jacobian, the state's scale and the static rest state. Imports only
:mod:`msg_defs`'s ROS-free constants; every other room of :mod:`sphere_sim` builds on it.
"""
