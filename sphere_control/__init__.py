"""The controllers of §5 and the studies that judge them, free of ROS.

Builds on the discrete kick model of :mod:`sphere_sim.kicks` (never on the continuous model's
internals): the basic and the extended controller, the normal's estimator, references, the
closed loop, perturbations and the evaluation of Fig. 13-15.
Its nodes are :mod:`sphere_twin.nodes.controller_node` and
:mod:`sphere_twin.nodes.reference_node`.
"""
