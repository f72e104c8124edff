"""Kicks as motion primitives (§4–5): designs, optimisation, characteristics, tables,
calibration, and the plants the simulator runs (the continuous model kicked by programmes, or
the kick table).

Builds the discrete model x_{t+1} = f(x_t, a_t, u_K) from simulated kicks. Imports
:mod:`sphere_sim.model`, :mod:`sphere_sim.integrate` and :mod:`sphere_sim.studies`.
"""
