"""The simulator holds simulated time at 0 until the nodes on sim time listen to /clock: a
reference that has not heard the clock when a short run ends would never have moved."""

import numpy as np
import pytest

from msg_defs.conversions import ns_from_time, surface_normal_from_msg
from msg_defs.device import NS_PER_S
from msg_defs.topics import CLOCK, DIAGNOSTICS, SPHERE_REFERENCE, SURFACE_NORMAL
from sphere_control.reference import sample
from sphere_sim.model.rotations import angle_between
from sphere_twin.processes import parameter_args
from sphere_twin.scenario import scenario_nodes, scenario_reference
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


SETPOINT_S = 0.5  # the scenario's setpoint, then eq. (64)
FOLLOWED_S = 2.0  # simulated seconds of the trajectory the reference is followed through
MIN_TRAJECTORY_STEP_RAD = 0.02  # how far from the setpoint eq. (64) has taken it by then


def test_a_scenario_starts_time_only_once_its_reference_listens_beside_another_listener(
        ros_nodes):
    """Another node on /clock (in the demo its recorder, here the probe) must not stand in for
    the reference: with a count of one, time started and a short run ended while the
    reference's discovery of the simulator lagged, and the reference held its setpoint. Once
    it listens, its publications follow /clock: each is the schedule at its stamp."""
    _, reference, simulator = scenario_nodes(SETPOINT_S, 'discrete', 2.0, 0,
                                             normal_subscribers=1, clock_subscribers=2)
    process = ros_nodes.start(simulator.executable, simulator.args)
    probe = TopicProbe(ros_nodes.domain_id, (SURFACE_NORMAL, DIAGNOSTICS, SPHERE_REFERENCE),
                       process)
    other_listener = probe.node.create_subscription(CLOCK.msg_type, CLOCK.name, lambda msg: None,
                                                    CLOCK.qos.to_profile())
    references = probe.messages[SPHERE_REFERENCE.name]
    try:
        probe.spin_until(lambda: other_listener.get_publisher_count() > 0, TIMEOUT_S,
                         'the simulator matched on /clock')
        reports, normals = probe.messages[DIAGNOSTICS.name], probe.messages[SURFACE_NORMAL.name]
        matched = len(reports)  # the reports from here on: the other listener is counted
        probe.spin_until(
            lambda: normals or sum('waiting for subscribers' in m.status[0].message
                                   for m in reports[matched:]) >= WAITING_REPORTS,
            TIMEOUT_S, f'{WAITING_REPORTS} waiting reports')
        assert normals == [], 'simulated time started before the reference listened'
        ros_nodes.start(reference.executable, reference.args)
        probe.spin_until(
            lambda: references and _stamp_s(references[-1]) >= SETPOINT_S + FOLLOWED_S,
            TIMEOUT_S, f'the reference at {SETPOINT_S + FOLLOWED_S:g} s')
    finally:
        probe.close()
    schedule = scenario_reference(SETPOINT_S)
    for msg in references:
        np.testing.assert_allclose(surface_normal_from_msg(msg),
                                   sample(schedule, _stamp_s(msg)).normal, atol=1e-12)
    setpoint = sample(schedule, 0.0).normal
    assert angle_between(surface_normal_from_msg(references[-1]), setpoint) > \
        MIN_TRAJECTORY_STEP_RAD


def _stamp_s(msg):
    return ns_from_time(msg.header.stamp) / NS_PER_S
