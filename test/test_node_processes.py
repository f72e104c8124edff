"""Node executables as separate processes on localhost: messages cross, signals stop cleanly."""

import signal

import pytest

from msg_defs.topics import SURFACE_NORMAL
from msg_defs.transforms import NO_TF_LINE, tf_message_type
from sphere_twin.monitor_summary import parse_summaries
from sphere_twin.processes import parameter_args, stop

pytestmark = pytest.mark.ros

# Start-up (interpreter, rclpy, DDS discovery) takes about a second; these are generous.
READY_TIMEOUT_S = 20.0
EXIT_TIMEOUT_S = 10.0
STARTED_LINE = 'publishing /sphere/surface_normal'


def test_monitor_receives_the_simulators_messages_and_exits_after_max_messages(ros_nodes):
    simulator = ros_nodes.start('simulator', parameter_args(publish_rate_hz=100.0))
    monitor = ros_nodes.start('monitor', parameter_args(max_messages=25))

    assert monitor.wait(READY_TIMEOUT_S) == 0
    assert parse_summaries(monitor.stdout_text()) == {SURFACE_NORMAL.name: 25}
    assert monitor.stdout_text().splitlines()[-1] == (
        'received 25 messages on /sphere/surface_normal')
    assert 'invalid message' not in monitor.stderr_text()
    # The simulator keeps running until told to stop, and then stops cleanly.
    assert simulator.running()
    assert stop(simulator) == 0


@pytest.mark.parametrize('signum', [signal.SIGINT, signal.SIGTERM], ids=['SIGINT', 'SIGTERM'])
def test_simulator_exits_cleanly_on_signal_to_its_pid(ros_nodes, signum):
    simulator = ros_nodes.start('simulator')
    simulator.wait_for_output(STARTED_LINE, READY_TIMEOUT_S)
    simulator.send_signal(signum)
    # On a crash, what the node printed (its threads' stacks) is the report.
    assert simulator.wait(EXIT_TIMEOUT_S) == 0, simulator.stderr_text()
    assert 'Traceback' not in simulator.stderr_text()
    # Started alone it runs the physics; without tf2_msgs it says once where the pose is.
    assert 'continuous plant' in simulator.stderr_text()
    assert simulator.stderr_text().count(NO_TF_LINE) == (tf_message_type() is None)


def test_monitor_stopped_by_sigterm_exits_cleanly_and_reports_its_count(ros_nodes):
    # No simulator in this domain: the monitor has nothing to count.
    monitor = ros_nodes.start('monitor')
    monitor.wait_for_output('messages on /sphere/surface_normal', READY_TIMEOUT_S)
    monitor.send_signal(signal.SIGTERM)
    assert monitor.wait(EXIT_TIMEOUT_S) == 0
    assert parse_summaries(monitor.stdout_text()) == {SURFACE_NORMAL.name: 0}
    assert 'Traceback' not in monitor.stderr_text()
