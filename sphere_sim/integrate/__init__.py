"""Time integration of an assembled model: the compiled Radau IIA and the library methods.

Takes a :class:`~sphere_sim.model.assembly.Model`, an initial state and a voltage programme, and
returns a trajectory with its cost. Imports only :mod:`sphere_sim.model`; does no I/O.
"""
