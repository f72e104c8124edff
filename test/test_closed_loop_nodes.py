"""Simulator, reference and controller as separate processes: a setpoint is reached over DDS."""

import math

import pytest

from msg_defs.conversions import surface_normal_from_msg
from msg_defs.topics import CONTROLLER_STATUS, SURFACE_NORMAL
from sphere_sim.kicks.discrete import normal_from_xy
from sphere_sim.model.rotations import angle_between
from sphere_twin.processes import parameter_args
from sphere_twin.testing import TopicProbe

pytestmark = pytest.mark.ros

SETPOINT_XY = (0.01, 0.02)  # Fig. 13
# Resting bands: the extended controller settles at the paper's 0.05 deg; the basic one, whose
# kicks are all full (0.73 deg), circles a band that narrow (Fig. 13) and is given about half a
# kick (docs/control.md: it settles at 0.34 deg).
PHI_MIN_DEG = {'basic': 0.35, 'extended': 0.05}
CLOSED_LOOP_TIMEOUT_S = 90.0


def _status_values(msg):
    status = msg.status[0]
    return {kv.key: kv.value for kv in status.values}


@pytest.mark.parametrize('controller', ['basic', 'extended'])
def test_lockstep_closed_loop_reaches_the_setpoint_and_rests(ros_nodes, controller):
    simulator = ros_nodes.start('simulator', parameter_args(plant='discrete', lockstep=True))
    ros_nodes.start('reference', parameter_args(setpoint_xy=list(SETPOINT_XY)))
    phi_min_deg = PHI_MIN_DEG[controller]
    # The extended one runs with reference preview: on a setpoint it aims at the setpoint.
    ros_nodes.start('controller', parameter_args(controller=controller,
                                                 phi_min_deg=phi_min_deg,
                                                 preview=controller == 'extended',
                                                 hold_each_sample=True))
    probe = TopicProbe(ros_nodes.domain_id, (CONTROLLER_STATUS, SURFACE_NORMAL), simulator)
    statuses = probe.messages[CONTROLLER_STATUS.name]
    try:
        def resting_after_kicks():
            return any(_status_values(m)['phase'] == 'resting'
                       and int(_status_values(m)['kicks']) > 0 for m in statuses[-5:])

        probe.spin_until(resting_after_kicks, CLOSED_LOOP_TIMEOUT_S, 'resting controller')
        values = _status_values(next(m for m in reversed(statuses)
                                     if _status_values(m)['phase'] == 'resting'))
        # With full kicks of 0.73 deg the controller can rest before the probe's subscription
        # to the normal has matched: wait for a sample taken after the rest.
        seen = len(probe.messages[SURFACE_NORMAL.name])
        probe.spin_until(lambda: len(probe.messages[SURFACE_NORMAL.name]) > seen,
                         CLOSED_LOOP_TIMEOUT_S, 'a surface normal after the rest')
        normal = surface_normal_from_msg(probe.messages[SURFACE_NORMAL.name][-1])
    finally:
        probe.close()
    error_deg = math.degrees(angle_between(normal, normal_from_xy(*SETPOINT_XY)))
    assert error_deg < phi_min_deg
    assert float(values['phi_deg']) < phi_min_deg
    # From level to 1.28 deg of tilt takes several kicks of at most 0.73 deg, not one.
    assert int(values['kicks']) >= 2
    # A setpoint stands still: nothing for the kicks to catch up with.
    assert float(values['reference_speed_ratio']) == 0.0
