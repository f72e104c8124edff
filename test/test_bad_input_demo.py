"""The demo's and the bag analyses' promises without a ROS graph: a user's mistake ends in one
line on stderr and status 2 before anything starts or is written; a bag its recorder did not
close is analysed with one warning that says what was read; long loops say their progress."""

import json
import os
import shutil
import time
from pathlib import Path

import pytest

from sphere_twin import cli, run_analysis
from sphere_twin.bag.locate import locate_bag
from sphere_twin.commands import demo
from sphere_twin.processes import MAX_DOMAIN_ID, MIN_DOMAIN_ID
from sphere_twin.run_analysis import load_run
from sphere_twin.scenario import offline_loop

# The example bag cut to this fraction of its MCAP file: a few seconds of the run, so that a
# replay of it is quick; the cut falls inside a chunk, as a killed recorder leaves it.
CUT_FRACTION = 8
# A user's mistake is refused at once: the demo used to wait out its 60 s start-up timeout.
REFUSED_WITHIN_S = 10.0


@pytest.fixture(scope='module')
def unclosed_bag(tmp_path_factory):
    """A copy of the example bag whose MCAP file ends an eighth of the way in, unclosed."""
    example = locate_bag('example').directory
    bag = tmp_path_factory.mktemp('cut') / 'cut_example'
    shutil.copytree(example, bag)
    (mcap,) = bag.glob('*.mcap')
    data = mcap.read_bytes()
    mcap.write_bytes(data[:len(data) // CUT_FRACTION])
    return bag


def _one_error_line(capsys, command):
    captured = capsys.readouterr()
    lines = captured.err.splitlines()
    assert len(lines) == 1, captured.err
    assert lines[0].startswith(f'sphere-twin {command}: error: '), lines[0]
    assert 'Traceback' not in captured.err + captured.out
    return lines[0]


# --- the demo refuses what cannot work, at once --------------------------------------------

def test_demo_bad_input_bags_dir_that_is_a_file_is_refused_at_once(tmp_path, capsys):
    a_file = tmp_path / 'not_a_dir'
    a_file.write_text('')
    started = time.monotonic()
    assert cli.main(['demo', '--bags-dir', str(a_file)]) == 2
    assert time.monotonic() - started < REFUSED_WITHIN_S
    line = _one_error_line(capsys, 'demo')
    assert line.endswith(f'--bags-dir: {a_file} is a file; give a directory')
    assert a_file.read_text() == ''


def test_demo_bad_input_a_plant_that_cannot_serve_the_fidelity_is_refused_at_once(
        tmp_path, capsys):
    bags = tmp_path / 'bags'
    started = time.monotonic()
    assert cli.main(['demo', '--plant', 'discrete', '--fidelity', 'sliding', '--bags-dir',
                     str(bags)]) == 2
    assert time.monotonic() - started < REFUSED_WITHIN_S
    line = _one_error_line(capsys, 'demo')
    assert "fidelity 'sliding' is served by the continuous plant, not the discrete one" in line
    assert not bags.exists()


def test_demo_bad_input_bags_dir_under_a_file_cannot_be_created(tmp_path, capsys):
    a_file = tmp_path / 'not_a_dir'
    a_file.write_text('')
    assert cli.main(['demo', '--bags-dir', str(a_file / 'bags')]) == 2
    assert _one_error_line(capsys, 'demo').endswith(
        f'cannot create {a_file / "bags"}: {a_file} is a file, not a directory')


def test_demo_bad_input_bags_dir_that_is_not_writable(tmp_path, capsys, monkeypatch):
    # The check asks the OS (os.access), which says yes to root whatever the mode: it is
    # asked to say no here, so the refusal is tested under any user.
    locked = tmp_path / 'locked'
    locked.mkdir(mode=0o500)
    monkeypatch.setattr(os, 'access', lambda path, mode: Path(path) != locked)
    assert cli.main(['demo', '--bags-dir', str(locked)]) == 2
    assert _one_error_line(capsys, 'demo').endswith(f'cannot write in {locked}: permission denied')
    assert list(locked.iterdir()) == []


@pytest.mark.parametrize('value', ['abc', '-1', '233', '1.5'])
def test_demo_bad_input_ros_domain_id_is_refused_before_anything_is_written(
        tmp_path, capsys, monkeypatch, value):
    monkeypatch.setenv('ROS_DOMAIN_ID', value)
    bags = tmp_path / 'bags'
    assert cli.main(['demo', '--bags-dir', str(bags)]) == 2
    line = _one_error_line(capsys, 'demo')
    assert f"ROS_DOMAIN_ID='{value}' is not a ROS domain id" in line
    assert not bags.exists()


def test_a_missing_bags_dir_is_created_and_a_writable_one_kept(tmp_path):
    assert demo.check_bags_dir(tmp_path / 'a' / 'b') == tmp_path / 'a' / 'b'
    assert (tmp_path / 'a' / 'b').is_dir()
    assert demo.check_bags_dir(tmp_path) == tmp_path


def test_the_demo_takes_ros_domain_id_from_the_environment_and_a_fresh_one_without():
    assert demo.demo_domain_id({'ROS_DOMAIN_ID': '7'}) == (7, 'from the environment')
    assert demo.demo_domain_id({'ROS_DOMAIN_ID': '0'}) == (0, 'from the environment')
    for unset in ({}, {'ROS_DOMAIN_ID': ''}):
        domain_id, origin = demo.demo_domain_id(unset)
        assert MIN_DOMAIN_ID <= domain_id <= MAX_DOMAIN_ID
        assert origin == 'fresh: ROS_DOMAIN_ID is unset'


# --- a bag that was not closed --------------------------------------------------------------

def _warning_line(err, command):
    lines = err.splitlines()
    warnings = [line for line in lines if line.startswith(f'sphere-twin {command}: warning: ')]
    assert len(warnings) == 1, err
    return warnings[0]


def test_report_on_an_unclosed_bag_warns_once_with_what_it_read(unclosed_bag, tmp_path, capsys):
    assert cli.main(['report', str(unclosed_bag), '--out', str(tmp_path)]) == 0
    captured = capsys.readouterr()
    assert len(captured.err.splitlines()) == 1, captured.err
    warning = _warning_line(captured.err, 'report')
    recorded = load_run(unclosed_bag)
    assert 'was not closed (' in warning and 'of the 23584 messages metadata.yaml lists' in warning
    assert f'surface normals from 0.00 to {recorded.normal_t_s[-1]:.2f} s' in warning
    assert warning.endswith(f'run `sphere-twin bag repair {unclosed_bag}` to close it')
    # The figures are those of the readable part, and the JSON keeps the warning.
    assert f'kicks: {len(recorded.kicks)}' in captured.out
    data = json.loads((tmp_path / 'cut_example_report.json').read_text())
    assert data['warning'] == warning.split('warning: ', 1)[1]


def test_replay_check_on_an_unclosed_bag_warns_and_says_its_progress(
        unclosed_bag, tmp_path, capsys, monkeypatch):
    # A progress line at every sample (every few seconds of wall time in use).
    monkeypatch.setattr(run_analysis, 'PROGRESS_PERIOD_S', 0.0)
    assert cli.main(['replay-check', str(unclosed_bag), '--plant', 'discrete',
                     '--out', str(tmp_path)]) == 0
    captured = capsys.readouterr()
    warning = _warning_line(captured.err, 'replay-check')
    assert 'was not closed' in warning and 'sphere-twin bag repair' in warning
    progress = [line for line in captured.err.splitlines()
                if line.startswith('replay-check: replaying: ')]
    assert len(progress) > 10
    assert progress[-1].endswith('s of the recording (100%)'), progress[-1]
    assert captured.out.splitlines()[-1].startswith('replay error: one kick ahead median ')


def test_a_closed_bag_gets_no_warning():
    example = locate_bag('example').directory
    assert run_analysis.unclosed_bag_warning(example, load_run(example)) is None


# --- the demo's summary: one source, the bag ------------------------------------------------

def test_the_demo_summary_takes_its_figures_from_the_bag_and_says_a_node_failed(unclosed_bag):
    """As after a recorder killed mid-run: the run went on to 33 s, the bag holds 5 s."""
    lines = []
    problems = demo._report_bag(unclosed_bag, 8.0, 33.0, lines.append, None,
                                ['recorder exited with -9'])
    text = '\n'.join(lines)
    assert problems == [], text
    recorded = load_run(unclosed_bag)
    bag_end_s = recorded.normal_t_s[-1]
    assert lines[0].startswith('demo: warning: ') and 'was not closed' in lines[0]
    assert lines[1] == ('demo: recorder exited with -9: the figures below are what the bag '
                        f'holds, up to {bag_end_s:.1f} s simulated (the run reached 33.0 s)')
    assert f'demo: {len(recorded.kicks)} kicks in {bag_end_s:.1f} s simulated' in text
    assert 'offline loop' not in text


# --- progress of the offline loop -----------------------------------------------------------

def test_the_offline_loop_reports_its_simulated_time_and_can_be_stopped():
    times = []
    offline_loop(0.2, 0.4, 'discrete', times.append)
    assert times[0] == 0.0 and times[-1] >= 0.35 and times == sorted(times)
    stop = demo.StopSignals()
    stop.signum = 15
    lines = []
    assert demo._offline_rms_rad(0.2, 0.4, 'discrete', 'table', stop, lines.append) is None
    assert lines[-1] == 'demo: got SIGTERM in the offline loop: no comparison with it'
