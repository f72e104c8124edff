"""SIGINT or SIGTERM at any moment ends every node with exit code 0 and no traceback.

Each node is signalled while it works: the simulator while it integrates kicks of the
continuous plant (unpaced and fed a kick every few milliseconds, it spends most of its time
inside the compiled integrator), the controller while samples stream in and it decides, the
reference while it publishes, the recorder while it writes, whose bag must then be complete.
"""

import signal
import time

import pytest

from msg_defs.topics import (
    CLOCK,
    CONTROLLER_STATUS,
    DIAGNOSTICS,
    PULSE_PROGRAM,
    SPHERE_REFERENCE,
    SURFACE_NORMAL,
)
from sphere_twin.bag.reader import (
    deserialize,
    has_footer,
    read_messages,
    read_metadata,
    storage_files,
)
from sphere_twin.processes import parameter_args
from sphere_twin.scenario import RunLog, scenario_nodes
from sphere_twin.testing import TopicProbe

pytestmark = pytest.mark.ros

READY_TIMEOUT_S = 60.0
# Every topic with a stamp that the stopped nodes publish, and the simulator's own two: the bag
# must hold each (the nodes are stopped once the recorder has said it records them all).
RECORDED_BEFORE_STOP = (SURFACE_NORMAL, CLOCK, SPHERE_REFERENCE, CONTROLLER_STATUS, PULSE_PROGRAM)
# A stop that takes long is not what these tests judge (exit status, no traceback): a node's
# shutdown waits up to 6 s for its publishing thread, and a loaded machine (six nodes at 5x
# real time beside the suite) can take several more seconds to leave the interpreter.
EXIT_TIMEOUT_S = 30.0
SIGNALS = [signal.SIGINT, signal.SIGTERM]
SIGNAL_IDS = ['SIGINT', 'SIGTERM']
# Wall times after the first kick at which the simulator is signalled: spread over a kick's
# compute (tens of ms, most of it in its first simulated milliseconds).
SIMULATOR_SIGNAL_DELAYS_S = (0.013, 0.171)
KICK_EVERY_S = 0.005
# The simulator starts once the recorder, the controller and the probe listen to the normal.
NORMAL_SUBSCRIBERS = 3
CLOCK_SUBSCRIBERS = 2  # and once the recorder and the reference listen to /clock
BUSY_FRACTION = 0.3  # of wall time integrating, by the simulator's periodic status


def _assert_clean_exit(process):
    assert process.wait(EXIT_TIMEOUT_S) == 0, process.stderr_text()[-2000:]
    assert 'Traceback' not in process.stderr_text() + process.stdout_text()


def _integrating_fraction(probe):
    for msg in reversed(probe.messages[DIAGNOSTICS.name]):
        values = {kv.key: kv.value for kv in msg.status[0].values}
        if 'integrating_fraction' in values:
            return float(values['integrating_fraction'])
    return 0.0


@pytest.mark.parametrize('delay_s', SIMULATOR_SIGNAL_DELAYS_S)
@pytest.mark.parametrize('signum', SIGNALS, ids=SIGNAL_IDS)
def test_the_simulator_stops_cleanly_in_the_middle_of_integrating(ros_nodes, signum, delay_s):
    from msg_defs.conversions import programme_to_msg
    from sphere_sim.kicks.lookup_table import load_kick_model

    simulator = ros_nodes.start('simulator', parameter_args(plant='continuous',
                                                           real_time_factor=0.0))
    simulator.wait_for_output('publishing /sphere/surface_normal', READY_TIMEOUT_S)
    kick = programme_to_msg(*load_kick_model().programme(0, 1.0).segments())
    probe = TopicProbe(ros_nodes.domain_id, (DIAGNOSTICS,), simulator)
    try:
        probe.wait_for_subscribers(PULSE_PROGRAM, READY_TIMEOUT_S)
        publisher = probe.publisher(PULSE_PROGRAM)
        # Kicks until the simulator's status shows it busy integrating, then on for delay_s.
        deadline, give_up = None, time.monotonic() + READY_TIMEOUT_S
        while deadline is None or time.monotonic() < deadline:
            publisher.publish(kick)
            probe.spin_once(KICK_EVERY_S)
            if deadline is None and _integrating_fraction(probe) > BUSY_FRACTION:
                deadline = time.monotonic() + delay_s
            assert simulator.running() and time.monotonic() < give_up
        simulator.send_signal(signum)
    finally:
        probe.close()
    _assert_clean_exit(simulator)
    assert simulator.stdout_text().splitlines()[-1].startswith('simulator: simulated')


@pytest.mark.parametrize('signum', SIGNALS, ids=SIGNAL_IDS)
def test_controller_reference_and_recorder_stop_cleanly_while_the_loop_runs(
        ros_nodes, tmp_path, signum):
    recorder = ros_nodes.start('recorder', parameter_args(output_dir=str(tmp_path / 'bag')))
    nodes = {spec.executable: ros_nodes.start(spec.executable, spec.args)
             for spec in scenario_nodes(1.0, 'discrete', 5.0, 0, NORMAL_SUBSCRIBERS,
                                       CLOCK_SUBSCRIBERS)}
    probe = TopicProbe(ros_nodes.domain_id, (SURFACE_NORMAL, CONTROLLER_STATUS))
    try:
        log = RunLog(probe)
        probe.spin_until(lambda: log.kicks() >= 3, READY_TIMEOUT_S, 'three kicks')
        # The probe hearing kicks does not mean the recorder does (discovery matches each
        # pair on its own): it says so with each topic's first message, and the loop kicks on.
        # The controller's status goes out at 5 Hz of wall time, so it may come last.
        for topic in RECORDED_BEFORE_STOP:
            recorder.wait_for_output(f'recording {topic.name} ', READY_TIMEOUT_S)
    finally:
        probe.close()
    # Each while the others still run: the controller amid samples, the reference on its
    # timer, the recorder amid the simulator's stream.
    for name in ('controller', 'reference'):
        nodes[name].send_signal(signum)
        _assert_clean_exit(nodes[name])
    recorder.send_signal(signum)
    _assert_clean_exit(recorder)
    assert nodes['simulator'].running()

    bag = tmp_path / 'bag'
    (path,) = storage_files(bag)
    assert has_footer(path)
    counts = {t['topic_metadata']['name']: t['message_count']
              for t in read_metadata(bag)['topics_with_message_count']}
    read = {}
    for message in read_messages(bag):
        read[message.topic] = read.get(message.topic, 0) + 1
    assert read == {topic: n for topic, n in counts.items() if n}
    assert read.get(SURFACE_NORMAL.name, 0) > 10, read
    # One clock rule: every stamp on every contract topic is simulated time (/clock), none is
    # the wall clock's (1.8e9 s), whoever published it.
    stamps = {}
    for message in read_messages(bag):
        msg = deserialize(message)
        stamp = msg.clock if message.topic == CLOCK.name else getattr(msg, 'header', None)
        if stamp is not None:
            stamp = getattr(stamp, 'stamp', stamp)
            stamps.setdefault(message.topic, []).append(stamp.sec + stamp.nanosec * 1e-9)
    assert {topic.name for topic in RECORDED_BEFORE_STOP} <= stamps.keys()
    simulated_s = max(stamps[CLOCK.name])
    assert all(0.0 <= t <= simulated_s + 1.0 for ts in stamps.values() for t in ts), {
        topic: max(ts) for topic, ts in stamps.items()}


# Gaps between the two SIGINTs of a Ctrl-C under `ros2 launch` (the terminal's to the whole
# group, launch's own): together, while the first one's shutdown runs, after the node has
# finished and Python is finalising.
DOUBLE_SIGINT_GAPS_S = (0.0, 0.02, 0.3)


@pytest.mark.parametrize('gap_s', DOUBLE_SIGINT_GAPS_S)
def test_every_node_stops_cleanly_when_sigint_comes_twice(ros_nodes, tmp_path, gap_s):
    nodes = {spec.executable: ros_nodes.start(spec.executable, spec.args)
             for spec in scenario_nodes(1.0, 'discrete', 5.0, 0, 1, 1)}
    nodes['recorder'] = ros_nodes.start('recorder', parameter_args(
        output_dir=str(tmp_path / 'bag')))
    nodes['monitor'] = ros_nodes.start('monitor')
    nodes['player'] = ros_nodes.start('player', parameter_args(
        bag='example', loop=True, publish_clock=False))
    nodes['simulator'].wait_for_output('publishing /sphere/surface_normal', READY_TIMEOUT_S)
    nodes['recorder'].wait_for_output('recording ', READY_TIMEOUT_S)
    for process in nodes.values():
        process.send_signal(signal.SIGINT)
    time.sleep(gap_s)
    for process in nodes.values():
        if process.running():
            process.send_signal(signal.SIGINT)
    for name, process in nodes.items():
        assert process.wait(EXIT_TIMEOUT_S) == 0, (name, process.stderr_text()[-2000:])
        assert 'Traceback' not in process.stderr_text() + process.stdout_text(), name
