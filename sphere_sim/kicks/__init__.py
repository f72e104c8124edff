"""Kicks as motion primitives (§4–5): designs, optimisation, characteristics, holding, tables.

Builds the discrete model x_{t+1} = f(x_t, a_t, u_K) from simulated kicks. Imports
:mod:`sphere_sim.model` and :mod:`sphere_sim.integrate`, not its sibling
:mod:`sphere_sim.studies`; the plants the simulator runs are in :mod:`sphere_sim.twin`, the
fitting to a device in :mod:`sphere_sim.fitting`.
"""
