"""Every node of the twin, one ``Node`` subclass per module, each thin over a ROS-free core.

``simulator`` (over :class:`sphere_sim.twin.runner.TwinRunner`), ``controller`` (over
:class:`sphere_control.kick_cycle.KickCycle`), ``reference`` (over :mod:`sphere_control.reference`),
``recorder`` and ``player`` (over :mod:`sphere_twin.bag`) and ``monitor``. The executables of
``setup.py`` (:mod:`~sphere_twin.nodes.executables`) start their ``main()`` once SIGINT
and SIGTERM are a clean stop; nothing outside this room imports it.
"""
