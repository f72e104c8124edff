"""``sphere-twin experiment``: the experiment protocol sent over the topics. On the lockstep twin
the quick protocol's bracket, decided on the wire, is what the recorded bag reads back and
holds the model's own threshold; a protocol over the voltage limit is refused in one line
before anything starts; Ctrl-C stops the nodes it started and exits with 130."""

import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from test_protocol import direct_threshold_v

from msg_defs.device import VOLTAGE_LIMIT_V
from sphere_twin import cli
from sphere_twin.commands.experiment import QUICK_BEAM, QUICK_RESOLUTION_V, QUICK_WIDTH_S

REPO = Path(__file__).resolve().parents[1]
DECIDED = re.compile(r'experiment: threshold of beam (\d), (\S+) ms pulses: (\S+) V '
                     r'\(not pulled in\) to (\S+) V \(pulled in\) \(decided on the wire\)')


@pytest.mark.ros
def test_the_quick_experiment_on_the_lockstep_twin_brackets_the_models_threshold(
        tmp_path, capsys, monkeypatch):
    from sphere_sim.model.parameters import load_parameter_set
    from sphere_twin.protocol_bag import read_protocol

    monkeypatch.delenv('ROS_DOMAIN_ID', raising=False)  # a fresh domain of its own
    bag = tmp_path / 'experiment'
    assert cli.main(['experiment', str(bag), '--twin', '--quick', '--params',
                     'calibrated']) == 0
    out = capsys.readouterr().out
    (decided,) = DECIDED.findall(out)
    beam, width_ms, below, above = decided
    assert (int(beam), float(width_ms)) == (QUICK_BEAM, QUICK_WIDTH_S * 1e3)
    (bracket,) = read_protocol(bag).brackets
    # What the command printed as decided on the wire is what the bag reads back.
    assert (bracket.beams, bracket.width_s) == ((QUICK_BEAM,), QUICK_WIDTH_S)
    assert (f'{bracket.not_pulled_in_v:.2f}', f'{bracket.pulled_in_v:.2f}') == (below, above)
    assert bracket.pulled_in_v - bracket.not_pulled_in_v <= QUICK_RESOLUTION_V
    assert bracket.contains(direct_threshold_v(load_parameter_set('calibrated')))
    assert 'experiment: OK: the bag reads back the 1 bracket(s) decided on the wire' in out
    # Every node it started was stopped by its PID and exited cleanly.
    assert 'stopping simulator (pid' in out


def test_a_protocol_over_the_voltage_limit_is_refused_in_one_line_before_anything_starts(
        tmp_path, capsys):
    bag = tmp_path / 'experiment'
    assert cli.main(['experiment', str(bag), '--twin', '--quick', '--bracket', '36',
                     '85']) == 2
    captured = capsys.readouterr()
    (line,) = captured.err.strip().splitlines()
    assert line.startswith('sphere-twin experiment: error: step 1 (threshold of beam 3')
    assert f'the limit is 0 to {VOLTAGE_LIMIT_V:g} V' in line
    assert captured.out == ''  # nothing started, not even announced
    assert not bag.exists()


@pytest.mark.ros
def test_ctrl_c_stops_the_nodes_it_started_and_exits_with_130(tmp_path):
    env = {**os.environ, 'PYTHONPATH': str(REPO), 'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST'}
    env.pop('ROS_DOMAIN_ID', None)
    process = subprocess.Popen(
        [sys.executable, '-m', 'sphere_twin.cli', 'experiment', str(tmp_path / 'experiment'),
         '--twin', '--quick'], cwd=REPO, env=env, stdout=subprocess.PIPE,
        stderr=subprocess.PIPE, text=True)
    lines = []
    try:
        assert process.stdout is not None
        deadline = time.monotonic() + 120.0
        for line in process.stdout:
            lines.append(line)
            if 'running the protocol' in line or time.monotonic() > deadline:
                break
        process.send_signal(signal.SIGINT)
        rest, _ = process.communicate(timeout=60.0)
    finally:
        if process.poll() is None:
            process.kill()
    lines += rest.splitlines(keepends=True)
    assert process.returncode == 130
    pids = [int(p) for line in lines for p in re.findall(r'started \w+ \(pid (\d+)\)', line)]
    assert len(pids) == 2
    (stopped,) = [line for line in lines if 'STOPPED' in line]
    assert stopped.startswith('experiment: STOPPED by SIGINT') and 'exit status 130' in stopped
    for pid in pids:  # gone, not left running
        with pytest.raises(ProcessLookupError):
            os.kill(pid, 0)
