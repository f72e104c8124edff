"""The simulated device: its physical model and everything computed from it, free of ROS.

Six rooms, each importing only the ones below it, and siblings not each other
(``test/test_layers.py`` keeps this true): :mod:`~sphere_sim.model` (parameters, scenes, the
parts, their assembly, the ladder's rungs) ← :mod:`~sphere_sim.integrate` (the solvers, the
tolerances) ← :mod:`~sphere_sim.studies` (whole runs: pull-in, validation figures) and
:mod:`~sphere_sim.kicks` (motion primitives, tables) ← :mod:`~sphere_sim.fitting` (calibration,
identification) and :mod:`~sphere_sim.twin` (the plants, their clock, the ladder measured, the
check beside the live twin). The data the rooms read
sit beside them: ``params/``, ``scenes/`` and ``tables/``.
"""
