"""Reports and open-loop replays of recorded runs."""

import json
import math
from pathlib import Path

import numpy as np
import pytest

from msg_defs.conversions import status_values
from msg_defs.topics import CONTROLLER_STATUS, PULSE_PROGRAM
from sphere_sim.kicks.discrete import normal_from_xy
from sphere_sim.model.scene import SCENES_DIR
from sphere_sim.twin.plants import LIVE_ERROR_BOUND_RAD, LIVE_METHOD
from sphere_twin.cli import build_parser
from sphere_twin.processes import parameter_args
from sphere_twin.run_analysis import (
    RecordedRun,
    errors_at_decisions_rad,
    reference_at,
    setpoint_segments,
    statistics,
)
from sphere_twin.testing import TopicProbe

EXAMPLE_BAG = Path(__file__).resolve().parents[1] / 'bags' / 'example'


def _write_bag(bag_dir, messages):
    """A bag of the contract's ``(topic, msg)`` messages, logged 1 ns apart in order, after a
    level surface normal (a bag needs one to be analysed)."""
    from rclpy.serialization import serialize_message

    from msg_defs.conversions import surface_normal_to_msg
    from msg_defs.topics import SURFACE_NORMAL
    from sphere_twin.bag.writer import BagWriter

    messages = [(SURFACE_NORMAL, surface_normal_to_msg(normal_from_xy(0.0, 0.0))), *messages]
    with BagWriter(bag_dir) as bag:
        for topic in {topic.name: topic for topic, _ in messages}.values():
            bag.add_contract_topic(topic)
        for k, (topic, msg) in enumerate(messages):
            bag.write(topic.name, serialize_message(msg), 1 + k)
    return bag_dir


def _run(errors_deg, period_s=0.02):
    """A synthetic run: the normal approaches a setpoint along x with the given errors."""
    target = normal_from_xy(0.02, 0.0)
    t = np.arange(len(errors_deg)) * period_s
    normals = np.array([normal_from_xy(0.02 - math.radians(e), 0.0) for e in errors_deg])
    return RecordedRun(t, normals, np.array([0.0, t[-1] / 2]), np.array([target, target]),
                       kicks=[(0.01, None, None), (0.05, None, None)], holds=[])


def test_statistics_of_a_synthetic_approach():
    run = _run([1.0, 0.5, 0.2, 0.08, 0.04, 0.03, 0.06, 0.02, 0.01, 0.01], period_s=0.1)
    stats = statistics(run, band_rad=math.radians(0.05))
    assert stats.kicks == 2
    # The last excursion above the band is at 0.6 s; settled from the next sample on.
    assert stats.settle_times_s == [pytest.approx(0.7)]
    assert math.degrees(stats.max_error_rad) == pytest.approx(1.0, rel=1e-3)  # x_sn is a sine
    assert math.degrees(stats.final_error_rad) == pytest.approx(0.01, rel=1e-3)


def test_the_error_where_the_controller_decided_is_read_at_those_samples_only():
    import dataclasses

    run = _run([1.0, 0.5, 0.2, 0.08, 0.04, 0.03, 0.06, 0.02, 0.01, 0.01], period_s=0.1)
    assert math.isnan(statistics(run).rms_decided_error_rad)  # no controller status recorded
    # Decided on the samples at 0.0, 0.3 and 0.7 s; 0.75 s is no sample and is ignored.
    run = dataclasses.replace(run, decision_t_s=np.array([0.0, 0.3, 0.7, 0.75]))
    times, errors = errors_at_decisions_rad(run)
    np.testing.assert_allclose(times, [0.0, 0.3, 0.7])
    np.testing.assert_allclose(np.degrees(errors), [1.0, 0.08, 0.02], rtol=1e-3)
    rms_deg = math.degrees(statistics(run).rms_decided_error_rad)
    assert rms_deg == pytest.approx(math.sqrt((1.0 + 0.08 ** 2 + 0.02 ** 2) / 3), rel=1e-3)


def test_a_run_that_never_settles_says_so():
    stats = statistics(_run([1.0, 0.9, 0.8, 0.7, 0.6, 0.5, 0.4, 0.3, 0.2, 0.1], period_s=0.1),
                       band_rad=math.radians(0.05))
    assert stats.settle_times_s == [None]


def test_setpoint_segments_split_where_the_reference_changes():
    run = _run([0.1] * 100)
    moved = normal_from_xy(0.0, 0.03)
    run = RecordedRun(run.normal_t_s, run.normals, np.array([0.0, 1.0, 1.1, 1.98]),
                      np.array([run.references[0], moved, moved, moved]), [], [])
    assert setpoint_segments(run) == [(0.0, 1.0), (1.0, pytest.approx(1.98))]


@pytest.mark.ros
def test_lockstep_recording_reports_and_replays_exactly(ros_nodes, tmp_path):
    from sphere_twin.commands import replay_check, report

    bag = tmp_path / 'run'
    ros_nodes.start('recorder', parameter_args(output_dir=str(bag)))
    ros_nodes.start('reference', parameter_args(setpoint_xy=[0.01, 0.02]))
    ros_nodes.start('controller', parameter_args(controller='extended', hold_each_sample=True))
    probe = TopicProbe(ros_nodes.domain_id, (CONTROLLER_STATUS,))
    statuses = probe.messages[CONTROLLER_STATUS.name]

    def decided():
        return sum(len(status_values(m.status[0])['decided_s'].split()) for m in statuses)

    try:
        # A lockstep run is over in a few seconds: the simulator starts only once the
        # controller's programmes have their recorder, or the bag may hold no kick.
        probe.wait_for_graph(PULSE_PROGRAM, publishers=1, subscribers=1, timeout_s=60.0)
        probe.process = ros_nodes.start('simulator', parameter_args(
            plant='discrete', lockstep=True, wait_for_subscribers=2))
        # Resting long enough that the setpoint's stretch counts for a settle time (lockstep
        # time runs one sample per hold).
        probe.spin_until(lambda: any(m.status[0].message == 'resting' for m in statuses[-3:])
                         and decided() > 80, 90.0, 'resting controller')
    finally:
        probe.close()
    ros_nodes.stop_all()
    failed = [f'{p.name} exited with {p.returncode}:\n{p.stderr_text()[-2000:]}'
              for p in ros_nodes.processes if p.returncode != 0]
    assert not failed, '\n'.join(failed)

    parser_args = type('Args', (), {'bag': bag, 'out': tmp_path, 'band_deg': 0.05})
    assert report.run(parser_args) == 0
    data = json.loads((tmp_path / 'run_report.json').read_text())
    # the setpoint is 1.28 deg away and a full kick turns 0.51 deg: three kicks at least
    assert data['kicks'] >= 3 and data['final_error_deg'] < 0.05
    assert data['settle_times_s'][0] is not None

    replay_args = build_parser().parse_args(['replay-check', str(bag), '--out', str(tmp_path),
                                             '--plant', 'discrete'])
    assert replay_check.run(replay_args) == 0
    replayed = json.loads((tmp_path / 'run_replay.json').read_text())
    # Lockstep: every programme ran at its stamp, so the table replays the run exactly.
    assert replayed['kicks'] == data['kicks'] and replayed['max_error_rad'] < 1e-12



@pytest.mark.ros
def test_continuous_plant_replays_a_recording_to_the_integrator_tolerance(ros_nodes, tmp_path):
    from sphere_twin.commands import replay_check

    bag = tmp_path / 'continuous'
    # The run starts 2 deg off level, off every kick's mirror line: from level a diagonal kick
    # runs along its mirror line, where the rounding decides to which side it lands, and the
    # run (from the simulator's rest) and the replay (from the rest of the recorded normal,
    # 2e-10 m apart in the bristles) end 1.3e-5 to 3.5e-5 rad apart at the live tolerance,
    # as the integrator's steps change in the last bits (docs/twin.md, "Recording and replaying").
    scene = tmp_path / 'tilted_rest.yaml'
    scene.write_text((SCENES_DIR / 'rest.yaml').read_text().replace(
        '{mode: rest}', '{mode: rest, sphere_angles_deg: [2.0, 0.0, 0.0]}'))
    ros_nodes.start('recorder', parameter_args(output_dir=str(bag)))
    ros_nodes.start('controller', parameter_args(controller='extended', hold_each_sample=True))
    # Over 2 deg away, so the first kicks are full ones: a short kick can fall on the high
    # pair's pull-in, where a state 1e-5 deg apart lands up to 0.1 deg apart (README, "An
    # example recording"), and what is tested here is the integrator, not that step.
    ros_nodes.start('reference', parameter_args(setpoint_xy=[0.04, 0.04]))
    probe = TopicProbe(ros_nodes.domain_id, (CONTROLLER_STATUS,))
    statuses = probe.messages[CONTROLLER_STATUS.name]
    # As in the lockstep recording: the kicks start once the recorder can hear them.
    probe.wait_for_graph(PULSE_PROGRAM, publishers=1, subscribers=1, timeout_s=60.0)
    probe.process = ros_nodes.start('simulator', parameter_args(
        plant='continuous', lockstep=True, wait_for_subscribers=2, scene=str(scene)))

    def kicked_enough():
        # The status's running count, not the kick messages seen: in lockstep the first kicks
        # can pass before the probe is matched. Two kicks can already land on the setpoint.
        if not statuses:
            return False
        latest = {kv.key: kv.value for kv in statuses[-1].status[0].values}
        kicks = int(latest.get('kicks', 0))
        return kicks >= 3 or (kicks >= 2 and latest.get('phase') == 'resting')

    try:
        probe.spin_until(kicked_enough, 120.0, 'three kicks, or two and rest')
    finally:
        probe.close()
    ros_nodes.stop_all()
    args = build_parser().parse_args(['replay-check', str(bag), '--out', str(tmp_path),
                                      '--plant', 'continuous'])
    assert replay_check.run(args) == 0
    replayed = json.loads((tmp_path / 'continuous_replay.json').read_text())
    # The replay integrates from the rest state of the first recorded normal (the run from the
    # scene's), sample by sample like the run, at the live tolerance, which holds a kick to a
    # hundredth of the noise study's sensor noise. Each kick adds its own integration error to
    # the difference: at most that bound per kick (measured: 4e-6 rad after 3 kicks, 9.9e-6
    # after 26, 7.8e-5 after the 214 of bags/example; 6e-10 rad after 3 at rtol 1e-6). The
    # recording runs on until the nodes are stopped, so its kick count varies.
    assert replayed['kicks'] >= 2
    assert replayed['max_error_rad'] < replayed['kicks'] * LIVE_ERROR_BOUND_RAD
    # The simulator said how it integrated, and the replay integrated alike.
    assert replayed['integration_method'] == LIVE_METHOD


def test_a_bag_whose_simulator_did_not_say_how_it_integrated_is_replayed_by_radau():
    """bags/example was recorded before the simulator's status named its method, when every
    twin ran the compiled Radau."""
    from sphere_twin.run_analysis import UNSTATED_INTEGRATION_METHOD, recorded_integration_method

    assert UNSTATED_INTEGRATION_METHOD == 'fast' != LIVE_METHOD
    assert recorded_integration_method(EXAMPLE_BAG) == 'fast'


def test_recorded_commands_that_break_the_rules_are_dropped_as_the_twin_dropped_them(tmp_path):
    """A recording is a boundary where data enters: a programme or a hold beyond the device's
    rules (msg_defs.voltage_rules) is skipped on reading, as the twin refused it when live."""
    from msg_defs.conversions import programme_to_msg, voltages_to_msg
    from msg_defs.topics import VOLTAGE_COMMAND
    from sphere_twin.run_analysis import load_run

    good = programme_to_msg([0.0, 1e-3], [[80.0, 0.0, 0.0, 0.0], [0.0] * 4])
    over = programme_to_msg([0.0, 1e-3], [[80.0, 0.0, 0.0, 0.0], [0.0] * 4])
    over.points[0].effort[0] = 90.0  # as a sender that skipped the rules would write it
    hold_over = voltages_to_msg([0.0] * 4)
    hold_over.effort = [0.0, 0.0, 85.0, 0.0]
    bag_dir = _write_bag(tmp_path / 'rules', [
        (PULSE_PROGRAM, good), (PULSE_PROGRAM, over), (VOLTAGE_COMMAND, hold_over),
        (VOLTAGE_COMMAND, voltages_to_msg([1.0] * 4))])
    run = load_run(bag_dir)
    assert len(run.kicks) == 1 and run.kicks[0][2][0][0] == 80.0
    assert len(run.holds) == 1 and run.holds[0][1].tolist() == [1.0] * 4


def test_programmes_start_where_the_device_reported_and_refused_ones_never_run(tmp_path):
    """A bag with /beams/programme_status: each programme starts where its report says (a
    late one later than its stamp), matched by stamp, in order for programmes that share one;
    a refused one is not replayed; one whose report was not recorded starts at its stamp."""
    from msg_defs.conversions import programme_event_to_msg, programme_to_msg, time_from_ns
    from msg_defs.programme_events import ProgrammeEvent, ProgrammeState
    from msg_defs.topics import PROGRAMME_STATUS
    from sphere_twin.run_analysis import load_run

    def programme(volts, stamp_s):
        return programme_to_msg([0.0, 1e-3], [[volts, 0.0, 0.0, 0.0], [0.0] * 4],
                                stamp=time_from_ns(round(stamp_s * 1e9)))

    sent = [programme(10.0, 0.5), programme(20.0, 0.0), programme(30.0, 0.0),
            programme(40.0, 0.8), programme(50.0, 0.9)]  # the last one's report was lost
    reports = [ProgrammeEvent(ProgrammeState.STARTED, 0.5, 1, 0.53),
               ProgrammeEvent(ProgrammeState.STARTED, 0.0, 2, 0.61),
               ProgrammeEvent(ProgrammeState.REFUSED, 0.0, 3, 0.62, 'overlaps'),
               ProgrammeEvent(ProgrammeState.ENDED, 0.0, 2, 0.611),
               ProgrammeEvent(ProgrammeState.STARTED, 0.8, 4, 0.8)]
    bag_dir = _write_bag(tmp_path / 'reported', [
        *((PULSE_PROGRAM, msg) for msg in sent),
        *((PROGRAMME_STATUS, programme_event_to_msg(event)) for event in reports)])
    run = load_run(bag_dir)
    assert [(start, volts[0][0]) for start, _, volts in run.kicks] == [
        (0.53, 10.0), (0.61, 20.0), (0.8, 40.0), (0.9, 50.0)]


def test_a_moving_reference_is_interpolated_and_a_jump_is_not_spread_back():
    """10 Hz samples of a line, a jump, the line again: between samples that continue the
    motion the reference is where it is at the time; from a jump to the next sample, and
    after the last one, the newest sample holds."""
    t = np.round(np.arange(0.0, 1.0, 0.1), 9)
    xy = np.stack([0.01 * t, np.zeros_like(t)], axis=1)
    xy[t >= 0.5, 1] = 0.02  # a jump of 0.02 at t = 0.5
    refs = np.array([normal_from_xy(*p) for p in xy])
    run = RecordedRun(np.array([0.0]), refs[:1], t, refs, [], [])
    at = reference_at(run, np.array([0.25, 0.45, 0.55, 0.75, 1.2]))
    np.testing.assert_allclose(at[0, :2], [0.0025, 0.0], atol=1e-9)  # renormalised chord
    np.testing.assert_allclose(at[1, :2], xy[4], atol=1e-12)  # the jump lies ahead: hold
    np.testing.assert_allclose(at[2, :2], xy[5], atol=1e-12)  # just after the jump: hold
    np.testing.assert_allclose(at[3, :2], [0.0075, 0.02], atol=1e-9)
    np.testing.assert_allclose(at[4, :2], xy[-1], atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(at, axis=1), 1.0, atol=1e-12)


def test_replay_check_replays_on_the_plant_that_recorded_the_bag(tmp_path):
    """bags/example was recorded from the physics: the plain replay-check replays it there,
    not on the kick table; a bag without the sphere's state came from the table."""
    import yaml

    from msg_defs.topics import SPHERE_STATE
    from sphere_twin.bag.locate import locate_bag
    from sphere_twin.commands.replay_check import default_plant

    example = locate_bag('example').directory
    assert default_plant(example, shipped_set=True) == 'continuous'
    metadata = yaml.safe_load((example / 'metadata.yaml').read_text())
    topics = metadata['rosbag2_bagfile_information']['topics_with_message_count']
    metadata['rosbag2_bagfile_information']['topics_with_message_count'] = [
        t for t in topics if t['topic_metadata']['name'] != SPHERE_STATE.name]
    (tmp_path / 'metadata.yaml').write_text(yaml.safe_dump(metadata))
    assert default_plant(tmp_path, shipped_set=True) == 'discrete'
    # Any set but the shipped one: the table cannot hold its kicks.
    assert default_plant(tmp_path, shipped_set=False) == 'continuous'
