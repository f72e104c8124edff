"""``sphere-twin demo``: the closed loop over DDS, recorded, stopped cleanly, summarised."""

import io
import os
import re
import signal
import subprocess
import threading
import time

import pytest

from msg_defs.topics import ALL_TOPICS, CLOCK
from sphere_sim.integrate.tolerances import LIVE_METHOD, LIVE_RTOL
from sphere_sim.model.fidelity import FULL, TABLE_RUNG
from sphere_twin.cli import build_parser
from sphere_twin.commands.demo import (
    DEFAULT_REAL_TIME_FACTOR,
    demo_nodes,
    demo_start_lines,
    run_demo,
)
from sphere_twin.nodes.simulator_node import CATCH_UP_SPEEDUP
from sphere_twin.processes import fresh_domain_id, resolve_executable

# Longest wait for a line of the signalled demo, and for its exit after the signal.
SIGNALLED_DEMO_WAIT_S = 120.0

pytestmark = pytest.mark.ros


@pytest.mark.parametrize('plant', ['continuous', 'discrete'])
def test_short_demo_runs_the_loop_records_a_bag_and_reports(tmp_path, plant):
    out = io.StringIO()
    code = run_demo(setpoint_s=3.0, trajectory_s=2.0, bags_dir=tmp_path, out=out, plant=plant)
    lines = out.getvalue().splitlines()
    text = '\n'.join(lines)
    assert code == 0, text
    started = [line.split()[2] for line in lines if line.startswith('demo: started')]
    assert started == ['recorder', 'controller', 'reference', 'simulator']
    assert all(line.endswith('exit code 0') for line in lines if line.startswith('demo: stopped'))
    kicks = re.search(r'demo: (\d+) kicks in ([\d.]+) s simulated', text)
    assert kicks and int(kicks.group(1)) > 0 and float(kicks.group(2)) >= 5.0
    # What to expect comes first, right after the domain; the summary names the rung again.
    rung = FULL.name if plant == 'continuous' else TABLE_RUNG
    assert lines[1:4] == demo_start_lines(plant, DEFAULT_REAL_TIME_FACTOR[plant], 3.0, 2.0, rung)
    assert re.search(rf'demo: \d+ kicks in [\d.]+ s simulated \([\d.]+ per second\) on the '
                     rf'{plant} plant, model {rung}, from the bag', text), text
    pace = re.search(r'demo: real-time factor: controller ([\d.]+), reference ([\d.]+), '
                     r'simulator ([\d.]+); late programmes: (\d+)', text)
    assert pace, text
    # The simulator, anchored to the wall clock, never runs ahead of the pace asked for (a
    # loaded machine lags a little). The others measure from the first sample they saw: one
    # that came while the simulator was catching up (at most CATCH_UP_SPEEDUP times the pace)
    # can make their span run faster than the pace.
    pace_asked = DEFAULT_REAL_TIME_FACTOR[plant]
    controller, reference, simulator = (float(f) for f in pace.groups()[:3])
    assert 0.5 * pace_asked < simulator < 1.01 * pace_asked
    for factor in (controller, reference):
        assert 0.5 * pace_asked < factor < CATCH_UP_SPEEDUP * pace_asked
    # The ROS loop tracks as the offline loop does on the same controller, plant, reference and
    # kick period (both errors where the loop decided, on settled states).
    rms = re.search(r'demo: trajectory RMS error ([\d.]+) deg \(offline loop: ([\d.]+) deg\)',
                    text)
    assert rms, text
    live, offline = float(rms.group(1)), float(rms.group(2))
    assert offline > 0.0 and live <= 1.5 * offline, text
    bag = re.search(r'demo: bag (\S+)', text).group(1)
    assert (tmp_path / bag.split('/')[-1] / 'metadata.yaml').is_file()
    assert list(tmp_path.glob('*_error.png'))
    assert lines[-1].startswith('demo: OK')


@pytest.mark.parametrize(('plant', 'rung', 'model'), [
    ('continuous', FULL.name, f'the full model of the paper at the live tolerance (rtol '
                              f'{LIVE_RTOL:g}, {LIVE_METHOD})'),
    ('discrete', TABLE_RUNG, "each kick's landing looked up in the kick tables"),
    ('continuous', 'sliding', f"the paper's model at the live tolerance (rtol {LIVE_RTOL:g}, "
                              f"{LIVE_METHOD}), "
                              'leaving out stiction and presliding')])
def test_the_demo_says_first_the_plant_its_rung_the_pace_and_the_wall_time(plant, rung, model):
    plant_line, pace_line, scenario_line = demo_start_lines(plant, 0.25, 8.0, 25.0, rung)
    assert plant_line.startswith(f'demo: {plant} plant, model {rung}: {model}')
    # 33 s of simulated time at a quarter of real time: 132 s of wall time.
    assert pace_line == ('demo: 33 s of simulated time at 0.25 of real time: about 2.2 min of '
                         'wall time, plus the offline loop')
    assert scenario_line.startswith('demo: scenario: setpoint (0.01, 0.02) for 8 s, then eq. '
                                    '(64)')
    assert 'about 20 s of wall time' in demo_start_lines(plant, 0.25, 3.0, 2.0, rung)[1]
    assert 'about 1.5 h of wall time' in demo_start_lines(plant, 0.5, 2700.0, 0.0, rung)[1]


def test_the_demo_simulator_waits_for_every_listener_of_the_clock(tmp_path):
    """The simulator sees only a count of /clock subscribers: it must count the recorder (it
    records every contract topic, /clock among them) as well as the reference, or the
    recorder alone starts a run the reference may not yet hear (it then holds its setpoint)."""
    *others, simulator = demo_nodes(tmp_path, 3.0, 2.0, 0)
    records_clock = [spec.executable for spec in others if spec.executable == 'recorder'
                     and CLOCK in ALL_TOPICS and not any('topics:=' in a for a in spec.args)]
    on_sim_time = [spec.executable for spec in others if 'use_sim_time:=True' in spec.args]
    assert (records_clock, on_sim_time) == (['recorder'], ['reference'])
    assert 'wait_for_clock_subscribers:=2' in simulator.args


def test_cli_parses_the_scenario_and_rejects_non_positive_durations():
    parser = build_parser()
    args = parser.parse_args(['demo', '--setpoint-s', '2.5', '--real-time-factor', '10'])
    # Plant and fidelity: '' leaves each to the other (plant_and_fidelity).
    assert (args.setpoint_s, args.real_time_factor, args.plant, args.fidelity) == \
        (2.5, 10.0, '', '')
    assert parser.parse_args(['demo', '--plant', 'discrete']).real_time_factor is None
    assert parser.parse_args(['demo', '--fidelity', 'sliding']).fidelity == 'sliding'
    with pytest.raises(SystemExit):
        parser.parse_args(['demo', '--plant', 'table'])
    with pytest.raises(SystemExit):
        parser.parse_args(['demo', '--fidelity', 'fastest'])
    with pytest.raises(SystemExit):
        parser.parse_args(['demo', '--trajectory-s', '0'])


def _lines_of(popen, lines):
    """Collect the child's stdout lines as they come (a thread: the test waits on them)."""
    def read():
        for raw in popen.stdout:
            lines.append(raw.rstrip('\n'))
    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    return reader


def _wait_for_line(lines, prefix, popen, after=0):
    deadline = time.monotonic() + SIGNALLED_DEMO_WAIT_S
    while time.monotonic() < deadline:
        found = [line for line in lines[after:] if line.startswith(prefix)]
        if found:
            return lines.index(found[0], after)
        assert popen.poll() is None, '\n'.join(lines)
        time.sleep(0.2)
    raise AssertionError(f'no line {prefix!r} within {SIGNALLED_DEMO_WAIT_S} s:\n'
                         + '\n'.join(lines))


def test_sigterm_stops_the_demo_as_sigint_does_on_the_domain_the_environment_names(tmp_path):
    """One short run (discrete plant, the cheapest) for three promises: ROS_DOMAIN_ID from the
    environment is used and said; a progress line comes while the loop runs; SIGTERM by PID
    stops every node cleanly, says so, summarises from the bag and exits with 143."""
    domain_id = fresh_domain_id()  # held by this process: no other run takes it meanwhile
    env = {**os.environ, 'ROS_DOMAIN_ID': str(domain_id),
           'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST', 'PYTHONUNBUFFERED': '1'}
    popen = subprocess.Popen(
        [resolve_executable('sphere-twin'), 'demo', '--plant', 'discrete', '--setpoint-s', '3',
         '--trajectory-s', '600', '--bags-dir', str(tmp_path)],
        env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    lines: list[str] = []
    reader = _lines_of(popen, lines)
    try:
        running = _wait_for_line(lines, 'demo: the loop runs', popen)
        _wait_for_line(lines, 'demo: progress: ', popen, after=running)
        popen.send_signal(signal.SIGTERM)
        code = popen.wait(SIGNALLED_DEMO_WAIT_S)
    finally:
        if popen.poll() is None:
            popen.kill()
            popen.wait()
    reader.join(5.0)
    stderr = popen.stderr.read()
    text = '\n'.join(lines)
    assert code == 143, text + stderr
    assert 'Traceback' not in stderr + text
    assert lines[0].startswith(f'demo: ROS_DOMAIN_ID={domain_id} (from the environment)')
    assert re.search(r'demo: progress: [\d.]+ of 603 s simulated, \d+ kicks, bag [\d.]+ MB',
                     text), text
    assert len([line for line in lines if line.startswith('demo: got SIGTERM at ')]) == 1
    stopped = [line for line in lines if line.startswith('demo: stopped ')]
    assert len(stopped) == 4 and all(line.endswith('exit code 0') for line in stopped), text
    assert re.search(r'demo: \d+ kicks in [\d.]+ s simulated .*, from the bag', text), text
    # No comparison: the run was cut short (the start lines only announced it).
    assert not [line for line in lines if line.startswith('demo: the offline loop')
                or 'offline loop:' in line], text
    assert lines[-1] == 'demo: STOPPED by SIGTERM, exit status 143'
    assert len(list(tmp_path.glob('demo_*/metadata.yaml'))) == 1  # the bag, closed


class _Farewell:
    """A stopped node as the demo's summary reads it: its name and its farewell line."""

    def __init__(self, name, text):
        self.name, self._text = name, text

    def stdout_text(self):
        return self._text


@pytest.mark.parametrize(('held', 'slipped'), [(0.17, True), (0.245, False)])
def test_the_summary_says_when_the_pace_slipped(held, slipped):
    from sphere_twin.commands.demo import _report_pace

    lines = []
    simulator = _Farewell('simulator', f'simulator: simulated 33.020 s, 3302 samples, 481 '
                                       f'programmes started (137 late), commands: 0 rejected, '
                                       f'0 dropped, 0 waiting for their sample; real-time '
                                       f'factor {held}; of wall')
    _report_pace([simulator, _Farewell('reference', 'real-time factor 0.17')], lines.append,
                 asked_factor=0.25)
    assert lines[0] == (f'demo: real-time factor: simulator {held:.2f}, reference 0.17; late '
                        'programmes: 137')
    assert (len(lines) == 2) == slipped
    if slipped:
        assert lines[1].startswith('demo: the pace slipped: asked 0.25, the simulator held 0.17')
