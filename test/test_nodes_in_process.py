"""Simulator and monitor node logic, driven directly in this process (callbacks, parameters)."""

import numpy as np
import pytest
import rclpy
from rclpy.parameter import Parameter
from sensor_msgs.msg import JointState

from msg_defs.conversions import surface_normal_to_msg, voltages_to_msg
from msg_defs.ros_env import DISCOVERY_RANGE_VAR
from sphere_sim.simulator_node import SimulatorNode
from sphere_twin.monitor_node import MonitorNode
from sphere_twin.processes import fresh_domain_id

pytestmark = pytest.mark.ros

TILTED_NORMAL = np.array([0.0, 0.6, 0.8])


class RecordingPlant:
    """Remembers every step and answers with a fixed, tilted normal."""

    def __init__(self):
        self.steps = []

    def step(self, dt_s, voltages_v):
        self.steps.append((dt_s, np.array(voltages_v)))
        return TILTED_NORMAL.copy()


@pytest.fixture
def context(monkeypatch):
    """An rclpy context of its own, on a fresh domain with localhost discovery."""
    monkeypatch.setenv(DISCOVERY_RANGE_VAR, 'LOCALHOST')
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=fresh_domain_id())
    yield context
    rclpy.try_shutdown(context=context)


@pytest.fixture
def simulator(context):
    node = SimulatorNode(plant=RecordingPlant(), context=context)
    yield node
    node.destroy_node()


def test_simulator_holds_valid_commands_and_steps_one_period(simulator):
    assert simulator.publish_rate_hz == 50.0
    simulator.on_timer()
    simulator.on_voltage_command(voltages_to_msg([10.0, 20.0, 30.0, 40.0]))
    simulator.on_timer()
    simulator.on_timer()
    steps = simulator.plant.steps
    assert [dt for dt, _ in steps] == [0.02, 0.02, 0.02]
    np.testing.assert_array_equal(steps[0][1], [0.0, 0.0, 0.0, 0.0])
    np.testing.assert_array_equal(steps[2][1], [10.0, 20.0, 30.0, 40.0])


@pytest.mark.parametrize('bad', [
    JointState(name=['beam_1', 'beam_2', 'beam_3'], effort=[1.0, 2.0, 3.0]),
    JointState(name=['beam_1', 'beam_2', 'beam_3', 'beam_4'], effort=[1.0, 2.0, 3.0, 81.0]),
    JointState(name=['beam_1', 'beam_2', 'beam_3', 'beam_4'], effort=[1.0, float('nan'), 3.0, 4.0]),
], ids=['three_beams', 'over_limit', 'nan'])
def test_simulator_drops_invalid_commands_and_keeps_the_last_valid_one(simulator, bad):
    simulator.on_voltage_command(voltages_to_msg([5.0, 5.0, 5.0, 5.0]))
    simulator.on_voltage_command(bad)
    simulator.on_timer()
    np.testing.assert_array_equal(simulator.plant.steps[-1][1], [5.0, 5.0, 5.0, 5.0])


def test_simulator_rate_comes_from_the_parameter_and_is_read_only(context):
    node = SimulatorNode(context=context,
                         parameter_overrides=[Parameter('publish_rate_hz', value=200.0)])
    try:
        assert node.period_s == pytest.approx(0.005)
        result = node.set_parameters([Parameter('publish_rate_hz', value=10.0)])[0]
        assert not result.successful
        assert node.get_parameter('publish_rate_hz').value == 200.0
    finally:
        node.destroy_node()


def test_monitor_completes_at_max_messages_and_stops_counting(context):
    node = MonitorNode(context=context, parameter_overrides=[Parameter('max_messages', value=3)])
    try:
        valid = surface_normal_to_msg(TILTED_NORMAL)
        invalid = surface_normal_to_msg(TILTED_NORMAL, frame_id='sphere')
        node.on_message(valid)
        node.on_message(invalid)
        assert not node.done.done()
        node.on_message(valid)
        assert node.done.done() and node.done.result() == 3
        node.on_message(valid)
        assert (node.count, node.invalid_count) == (3, 1)
        np.testing.assert_array_equal(node.latest_normal, TILTED_NORMAL)
        assert node.summary() == 'received 3 messages on /sphere/surface_normal'
    finally:
        node.destroy_node()
