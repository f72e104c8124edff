"""The simulated device: its physical model and everything computed from it, free of ROS.

Five rooms, each importing only the ones before it (``test/test_layers.py`` keeps this true):
:mod:`~sphere_sim.model` (parameters, scenes, the parts, their assembly) ←
:mod:`~sphere_sim.integrate` (the solvers) ← :mod:`~sphere_sim.studies` (whole runs: pull-in,
validation figures) ← :mod:`~sphere_sim.kicks` (motion primitives, tables, calibration) ←
:mod:`~sphere_sim.twin` (the plants, their clock and the simulator node). The data the rooms read
sit beside them: ``params/``, ``scenes/`` and ``tables/``.
"""
