"""What the simulator node runs, in plain Python: the plants (:mod:`~sphere_sim.twin.plants`),
chosen by name, their clock and command queue (:mod:`~sphere_sim.twin.runner`), the limit on
their reports; the ladder of models measured (:mod:`~sphere_sim.twin.ladder`) and the full model
run beside the twin (:mod:`~sphere_sim.twin.fidelity_check`).

The node itself is :mod:`sphere_twin.nodes.simulator_node`. May import the rooms below it
(model, integrate, studies, kicks) and :mod:`msg_defs`; not its sibling, fitting.
"""
