"""Whole runs of the model read in the paper's terms: a scene end to end, pull-in, validation.

Imports :mod:`sphere_sim.model` and :mod:`sphere_sim.integrate`, nothing above them.
"""
