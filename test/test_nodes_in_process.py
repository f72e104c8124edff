"""Simulator and monitor node logic, driven directly in this process (callbacks, parameters)."""

import time

import numpy as np
import pytest
from builtin_interfaces.msg import Duration
from rclpy.parameter import Parameter
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from msg_defs.conversions import programme_to_msg, surface_normal_to_msg, voltages_to_msg
from sphere_sim.twin.plants import PlantSnapshot
from sphere_twin.nodes.monitor_node import MonitorNode
from sphere_twin.nodes.simulator_node import SimulatorNode

pytestmark = pytest.mark.ros

TILTED_NORMAL = np.array([0.0, 0.6, 0.8])


class RecordingPlant:
    """Remembers every command and advance, and answers with a fixed, tilted normal."""

    def __init__(self):
        self.time_s = 0.0
        self.busy_until_s = 0.0
        self.held = []
        self.programmes = []
        self.voltages_v = np.zeros(4)

    def hold(self, voltages_v):
        self.held.append((self.time_s, np.array(voltages_v)))
        self.voltages_v = np.array(voltages_v)

    def run_programme(self, programme):
        self.programmes.append((self.time_s, programme))

    def advance(self, t_end_s):
        self.time_s = t_end_s

    def snapshot(self):
        return PlantSnapshot(self.time_s, TILTED_NORMAL.copy(), self.voltages_v.copy())


@pytest.fixture
def simulator(context):
    """Unpaced: each call of on_timer is one sample, whatever the wall clock."""
    node = SimulatorNode(plant=RecordingPlant(), context=context,
                         parameter_overrides=[Parameter('real_time_factor', value=0.0)])
    yield node
    node.destroy_node()


def test_a_paced_simulator_never_runs_ahead_of_the_wall_clock_and_catches_up(context):
    node = SimulatorNode(plant=RecordingPlant(), context=context,
                         parameter_overrides=[Parameter('real_time_factor', value=1.0)])
    try:
        started = time.perf_counter()
        while time.perf_counter() - started < 0.2:  # called far more often than due
            node.on_timer()
        period = node.period_s
        assert node.runner.time_s == pytest.approx(0.2, abs=period + 1e-9)
        time.sleep(0.1)  # falls behind by several samples
        before = node.runner.time_s
        for _ in range(3):
            node.on_timer()
        # Each call while behind makes one sample: caught up one sample per call, not all.
        assert node.runner.time_s - before == pytest.approx(3 * period)
    finally:
        node.destroy_node()


def test_simulator_holds_valid_commands_from_the_next_sample_on(simulator):
    assert simulator.publish_rate_hz == 100.0  # the sensor rate a 60 ms kick cycle needs
    simulator.on_timer()  # the initial sample, at t = 0
    simulator.on_voltage_command(voltages_to_msg([10.0, 20.0, 30.0, 40.0]))
    simulator.on_timer()
    simulator.on_timer()
    plant = simulator.runner.plant
    assert plant.time_s == pytest.approx(0.02)
    assert len(plant.held) == 1
    np.testing.assert_array_equal(plant.held[0][1], [10.0, 20.0, 30.0, 40.0])


def test_simulator_starts_a_valid_programme(simulator):
    simulator.on_timer()
    simulator.on_pulse_program(programme_to_msg([0.0, 1e-3, 3e-3],
                                                [[35, 35, 80, 80], [35, 35, 0, 0], [0] * 4]))
    simulator.on_timer()
    (_t_s, programme), = simulator.runner.plant.programmes
    assert programme.duration_s == pytest.approx(3e-3)
    np.testing.assert_array_equal(programme.voltages_at(0.5e-3), [35, 35, 80, 80])


def _programme_msg(names, points):
    msg = JointTrajectory(joint_names=names)
    for t, effort in points:
        sec, nanosec = divmod(round(t * 1e9), 1_000_000_000)
        msg.points.append(JointTrajectoryPoint(effort=effort, time_from_start=Duration(
            sec=int(sec), nanosec=int(nanosec))))
    return msg


BEAMS = ['beam_1', 'beam_2', 'beam_3', 'beam_4']
BAD_VOLTAGES = [
    JointState(name=['beam_1', 'beam_2', 'beam_3'], effort=[1.0, 2.0, 3.0]),
    JointState(name=BEAMS, effort=[1.0, 2.0, 3.0, 81.0]),
    JointState(name=BEAMS, effort=[1.0, float('nan'), 3.0, 4.0]),
    JointState(name=BEAMS, effort=[1.0, float('inf'), 3.0, 4.0]),
    JointState(name=BEAMS, effort=[1.0, -2.0, 3.0, 4.0]),
    JointState(name=['beam_1', 'beam_2', 'beam_3', 'beam_9'], effort=[1.0, 2.0, 3.0, 4.0]),
    JointState(name=BEAMS, effort=[1.0, 2.0, 3.0]),
]
BAD_PROGRAMMES = [
    _programme_msg(BEAMS, [(1e-3, [10.0] * 4), (0.5e-3, [0.0] * 4)]),  # times decrease
    _programme_msg(BEAMS, [(1e-3, [10.0] * 4), (1e-3, [0.0] * 4)]),  # times repeat
    _programme_msg(BEAMS, [(0.0, [10.0, 90.0, 0, 0]), (1e-3, [0.0] * 4)]),  # above limit
    _programme_msg(BEAMS, [(0.0, [10.0, -5.0, 0, 0]), (1e-3, [0.0] * 4)]),  # negative volts
    _programme_msg(BEAMS, [(0.0, [10.0, float('nan'), 0, 0]), (1e-3, [0.0] * 4)]),
    _programme_msg(BEAMS, [(0.0, [10.0, 10.0, 10.0]), (1e-3, [0.0] * 4)]),  # wrong length
    _programme_msg(['beam_1', 'beam_2', 'beam_3', 'beam_x'], [(0.0, [1.0] * 4),
                                                                (1e-3, [0.0] * 4)]),
    _programme_msg(BEAMS, [(0.0, [10.0] * 4)]),  # never switches off
    _programme_msg(BEAMS, []),  # empty
]


@pytest.mark.parametrize('bad', BAD_VOLTAGES)
def test_simulator_rejects_bad_voltage_commands_before_the_plant(simulator, bad):
    simulator.on_voltage_command(voltages_to_msg([5.0, 5.0, 5.0, 5.0]))
    simulator.on_voltage_command(bad)
    simulator.on_timer()
    plant = simulator.runner.plant
    assert len(plant.held) == 1 and np.all(plant.held[-1][1] == 5.0)
    assert simulator.runner.counters.rejected == 1


@pytest.mark.parametrize('bad', BAD_PROGRAMMES)
def test_simulator_rejects_bad_programmes_before_the_plant(simulator, bad):
    simulator.on_pulse_program(bad)
    simulator.on_timer()
    assert simulator.runner.plant.programmes == []
    assert simulator.runner.counters.rejected == 1


def test_rate_noise_and_pace_change_at_run_time_and_the_fixed_parameters_say_why(context):
    node = SimulatorNode(plant=RecordingPlant(), context=context,
                         parameter_overrides=[Parameter('publish_rate_hz', value=200.0),
                                              Parameter('real_time_factor', value=0.0)])
    try:
        for _ in range(3):
            node.on_timer()
        assert node.runner.time_s == pytest.approx(0.010)
        # As `ros2 param set /simulator publish_rate_hz 20` sends it: an integer.
        assert node.set_parameters([Parameter('publish_rate_hz', value=20)])[0].successful
        node.on_timer()
        node.on_timer()
        # The grid continues from the simulated now at the new period.
        assert node.runner.time_s == pytest.approx(0.010 + 2 * 0.05, abs=1e-12)

        assert node.runner.measure(TILTED_NORMAL) == pytest.approx(TILTED_NORMAL)
        assert node.set_parameters([Parameter('noise_std_rad', value=0.01)])[0].successful
        errors = [np.arccos(np.clip(node.runner.measure(TILTED_NORMAL) @ TILTED_NORMAL, -1, 1))
                  for _ in range(400)]
        # Two tangential axes of 0.01 rad each: the angle's RMS is 0.01 * sqrt(2).
        assert np.sqrt(np.mean(np.square(errors))) == pytest.approx(0.01 * np.sqrt(2), rel=0.15)

        # Paced from the simulated now on: no burst to catch up on the time run unpaced.
        assert node.set_parameters([Parameter('real_time_factor', value=1.0)])[0].successful
        assert node.paced
        before, started = node.runner.time_s, time.perf_counter()
        while time.perf_counter() - started < 0.3:
            node.on_timer()
        assert node.runner.time_s - before == pytest.approx(0.3, abs=0.05 + 1e-9)

        # Checked as at start-up, and left as it was when refused.
        refused = node.set_parameters([Parameter('publish_rate_hz', value='fast')])[0]
        assert not refused.successful and 'must be a number' in refused.reason
        assert not node.set_parameters([Parameter('noise_std_rad', value=0.5)])[0].successful
        assert node.runner.period_s == 0.05 and node.runner.noise_std_rad == 0.01
        fixed = node.set_parameters([Parameter('seed', value=3)])[0]
        assert not fixed.successful and 'read-only' in fixed.reason
        (seed,) = node.describe_parameters(['seed'])
        assert seed.read_only and 'reproducible' in seed.additional_constraints
        (plant,) = node.describe_parameters(['plant'])
        assert plant.read_only and 'start-up' in plant.additional_constraints
    finally:
        node.destroy_node()


def test_the_simulator_refuses_to_follow_the_clock_it_publishes_at_run_time(context):
    """`ros2 param set /simulator use_sim_time true` was taken silently and froze the twin:
    the node clock then waited for the /clock that only its own sampling publishes. It is
    refused as at start-up, with the reason; false (what it is) is still taken."""
    node = SimulatorNode(plant=RecordingPlant(), context=context,
                         parameter_overrides=[Parameter('real_time_factor', value=0.0)])
    try:
        refused = node.set_parameters([Parameter('use_sim_time', value=True)])[0]
        assert not refused.successful
        assert refused.reason.startswith('parameter use_sim_time = True refused: the '
                                         'simulator is the clock (it publishes /clock)')
        assert node.get_parameter('use_sim_time').value is False
        for _ in range(2):
            node.on_timer()
        assert node.runner.time_s > 0.0  # still sampling on its own pace
        assert node.set_parameters([Parameter('use_sim_time', value=False)])[0].successful
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


@pytest.mark.parametrize('hold_each_sample', [False, True])
def test_a_resting_controller_sends_0_v_once_per_rest_and_batches_its_status(context,
                                                                             hold_each_sample):
    """At rest on the reference, 0 V goes out when the rest begins (for every sample only
    when asked: a lockstep simulator's time runs on those); the status, at its own wall-clock
    rate, lists every sample decided on since the one before."""
    from diagnostic_msgs.msg import DiagnosticStatus

    from msg_defs.conversions import status_values
    from sphere_twin.nodes.controller_node import ControllerNode

    node = ControllerNode(context=context, parameter_overrides=[
        Parameter('hold_each_sample', value=hold_each_sample)])
    holds, statuses = [], []
    node._voltage_pub.publish = holds.append
    node._status_pub.publish = statuses.append
    try:
        level = np.array([0.0, 0.0, 1.0])
        node.on_reference(surface_normal_to_msg(level))
        stamps_s = [0.01 * k for k in range(1, 21)]
        for t_s in stamps_s[:10]:
            node.on_normal(surface_normal_to_msg(level, _stamp(t_s)))
        node.on_status_timer()
        for t_s in stamps_s[10:]:
            node.on_normal(surface_normal_to_msg(level, _stamp(t_s)))
        node.on_status_timer()
    finally:
        node.destroy_node()
    assert len(holds) == (20 if hold_each_sample else 1)
    assert all(list(msg.effort) == [0.0] * 4 for msg in holds)
    assert len(statuses) == 2
    decided = [[float(t) for t in status_values(msg.status[0])['decided_s'].split()]
               for msg in statuses]
    assert decided == [pytest.approx(stamps_s[:10]), pytest.approx(stamps_s[10:])]
    assert all(status_values(msg.status[0])['kicked_s'] == '' for msg in statuses)
    last = statuses[-1].status[0]
    assert last.message == 'resting' and last.level == DiagnosticStatus.OK


def test_a_hold_a_lockstep_simulator_never_took_is_sent_again_after_the_stale_timeout(
        context, monkeypatch):
    """With hold_each_sample, repeats of the sample already held send nothing while the hold
    may still be on its way; a repeat more than stale_timeout_s of wall time after it sends it
    again (the simulator is still waiting: it never took it), and then waits as long again."""
    from sphere_twin.nodes import controller_node
    from sphere_twin.nodes.controller_node import ControllerNode

    wall_s = [100.0]
    monkeypatch.setattr(controller_node.time, 'monotonic', lambda: wall_s[0])
    node = ControllerNode(context=context, parameter_overrides=[
        Parameter('hold_each_sample', value=True), Parameter('stale_timeout_s', value=1.0)])
    holds = []
    node._voltage_pub.publish = holds.append
    try:
        level = np.array([0.0, 0.0, 1.0])
        node.on_reference(surface_normal_to_msg(level))
        sent = []
        for wall in (100.0, 100.2, 100.4, 100.9, 101.1, 101.3, 102.0):
            wall_s[0] = wall
            node.on_normal(surface_normal_to_msg(level, _stamp(0.29)))  # the idle repeats
            sent.append(len(holds))
        wall_s[0] = 102.4
        node.on_normal(surface_normal_to_msg(level, _stamp(0.30)))  # the simulator moved on
    finally:
        node.destroy_node()
    assert sent == [1, 1, 1, 1, 2, 2, 2]
    assert len(holds) == 3
    assert [msg.header.stamp.nanosec for msg in holds] == [290_000_000] * 2 + [300_000_000]


def _stamp(t_s):
    from msg_defs.conversions import time_from_ns

    return time_from_ns(round(t_s * 1e9))


def test_with_check_fidelity_the_simulator_says_how_far_each_kick_lands_from_the_full_model(
        context):
    """check_fidelity:=true runs the full model beside the plant in a process of its own; the
    status publishes the rung that served the kicks and the divergence, the final line says it."""
    from sphere_sim.kicks.design import KICK_RELAXATION, cardan_of_normal
    from sphere_sim.kicks.lookup_table import LookupTable
    from sphere_sim.model.assembly import assemble
    from sphere_sim.model.initial_state import rest_state
    from sphere_sim.model.scene import load_scene
    from sphere_sim.twin.ladder import tilted_normal
    from sphere_sim.twin.plants import ContinuousPlant

    model = assemble(load_scene('rest'))
    normal = tilted_normal(20.0, 20.0)
    plant = ContinuousPlant(model, rest_state(model, cardan_of_normal(normal),
                                              relaxation=KICK_RELAXATION))
    node = SimulatorNode(plant=plant, context=context, parameter_overrides=[
        Parameter('real_time_factor', value=0.0), Parameter('check_fidelity', value=True)])
    try:
        node.on_timer()
        node.on_pulse_program(programme_to_msg(
            *LookupTable.load().programme(0, 1.0, normal).segments()))
        for _ in range(8):  # the kick's 60 ms window and a sample
            node.on_timer()
        values = dict(node.status_values())
        assert values['fidelity'] == 'full' and values['programmes'] == 1
        line = node.summary()  # waits for the reference of the kick that landed
        values = dict(node.status_values())
        assert values['fidelity_checked'] == 1 and values['fidelity_skipped'] == 0
        divergence = float(values['fidelity_divergence_max_rad'])
        assert 0.0 <= divergence < 1e-4  # the live tolerance, off the mirror lines
        assert 'model full; fidelity check: 1 kicks against the full model' in line
    finally:
        node.destroy_node()


def test_the_fidelity_parameter_picks_the_rung_that_serves_the_kicks(context):
    """fidelity:=sliding builds the continuous plant on the sliding rung: the status and the
    final line name it; a plant that cannot serve the rung is refused before anything is
    built, in one line naming both."""
    from sphere_sim.twin.plants import PlantError

    node = SimulatorNode(context=context, parameter_overrides=[
        Parameter('fidelity', value='sliding'), Parameter('real_time_factor', value=0.0)])
    try:
        assert not node.runner.plant.model.has_bristles
        node.on_timer()
        assert dict(node.status_values())['fidelity'] == 'sliding'
        assert '; model sliding' in node.summary()
    finally:
        node.destroy_node()
    with pytest.raises(PlantError, match=r"fidelity 'sliding' .* discrete") as info:
        SimulatorNode(context=context, parameter_overrides=[
            Parameter('plant', value='discrete'), Parameter('fidelity', value='sliding')])
    assert '\n' not in str(info.value)
