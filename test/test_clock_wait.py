"""The simulator holds simulated time at 0 until the nodes on sim time listen to /clock: a
reference that has not heard the clock when a short run ends would never have moved."""

import pytest

from msg_defs.topics import CLOCK, DIAGNOSTICS, SURFACE_NORMAL
from sphere_twin.processes import parameter_args
from sphere_twin.testing import TopicProbe

pytestmark = pytest.mark.ros

TIMEOUT_S = 60.0
WAITING_REPORTS = 3  # periodic status reports that say it waits, with no sample published


def test_simulated_time_starts_only_once_clock_has_its_listener(ros_nodes):
    simulator = ros_nodes.start('simulator', parameter_args(
        plant='discrete', real_time_factor=2.0, wait_for_clock_subscribers=1))
    watcher = TopicProbe(ros_nodes.domain_id, (SURFACE_NORMAL, DIAGNOSTICS), simulator)
    clock_listener = None
    try:
        reports = watcher.messages[DIAGNOSTICS.name]
        watcher.spin_until(
            lambda: sum('waiting for subscribers' in m.status[0].message for m in reports)
            >= WAITING_REPORTS, TIMEOUT_S, f'{WAITING_REPORTS} waiting reports')
        assert watcher.messages[SURFACE_NORMAL.name] == []
        clock_listener = TopicProbe(ros_nodes.domain_id, (CLOCK,), simulator)
        watcher.spin_until(lambda: len(watcher.messages[SURFACE_NORMAL.name]) >= 5, TIMEOUT_S,
                           'samples once /clock has a listener')
        clock_listener.spin_until(lambda: clock_listener.messages[CLOCK.name], TIMEOUT_S,
                                  'the clock')
    finally:
        watcher.close()
        if clock_listener is not None:
            clock_listener.close()
    ros_nodes.stop_all()
    assert simulator.returncode == 0
    assert 'on /clock: simulated time starts' in simulator.stdout_text() + \
        simulator.stderr_text()
