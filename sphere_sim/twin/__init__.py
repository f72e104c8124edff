"""What the simulator node runs, in plain Python: the plant chosen by name, its clock and
command queue (:mod:`~sphere_sim.twin.runner`), and the limit on its reports.

The node itself is :mod:`sphere_twin.nodes.simulator_node`. May import every other room of
:mod:`sphere_sim` and :mod:`msg_defs`.
"""
