"""The process supervisor: child environment, domain ids, stopping by PID with escalation."""

import itertools
import os
import signal
import sys
import time

import pytest

from sphere_twin.node_runtime.ros_env import DISCOVERY_RANGE_VAR, DOMAIN_ID_VAR
from sphere_twin.processes import (
    MAX_DOMAIN_ID,
    MIN_DOMAIN_ID,
    child_environment,
    fresh_domain_id,
    parameter_args,
    stop,
)

STOP_TIMEOUT_S = 0.5
READY_TIMEOUT_S = 10.0

# Children that install their signal dispositions, then say so and wait to be signalled.
IGNORES_SIGINT_EXITS_ON_SIGTERM = '''
import signal, sys, time
signal.signal(signal.SIGINT, signal.SIG_IGN)
signal.signal(signal.SIGTERM, lambda signum, frame: sys.exit(0))
print('ready', flush=True)
time.sleep(60)
'''
IGNORES_SIGINT_AND_SIGTERM = '''
import signal, time
signal.signal(signal.SIGINT, signal.SIG_IGN)
signal.signal(signal.SIGTERM, signal.SIG_IGN)
print('ready', flush=True)
time.sleep(60)
'''


def _environ_of(pid):
    with open(f'/proc/{pid}/environ', 'rb') as file:
        entries = file.read().split(b'\0')
    return dict(entry.decode().split('=', 1) for entry in entries if b'=' in entry)


def test_child_environment_adds_localhost_and_domain_but_keeps_an_explicit_range():
    env = child_environment(42, base_env={'PATH': '/bin'})
    assert env[DISCOVERY_RANGE_VAR] == 'LOCALHOST'
    assert env[DOMAIN_ID_VAR] == '42'
    assert env['PATH'] == '/bin'
    # A range the caller chose on purpose is theirs to keep (only the supervisor's default
    # is LOCALHOST); both the caller's environment and explicit overrides count.
    assert child_environment(3, base_env={DISCOVERY_RANGE_VAR: 'OFF'})[DISCOVERY_RANGE_VAR] == 'OFF'
    overridden = child_environment(3, env_overrides={DISCOVERY_RANGE_VAR: 'OFF'}, base_env={})
    assert overridden[DISCOVERY_RANGE_VAR] == 'OFF'
    # The domain id is always the supervisor's, whatever the caller's environment says.
    assert child_environment(5, base_env={DOMAIN_ID_VAR: '0'})[DOMAIN_ID_VAR] == '5'


def test_fresh_domain_ids_stay_in_range_and_differ_between_calls():
    ids = [fresh_domain_id() for _ in range(2 * (MAX_DOMAIN_ID - MIN_DOMAIN_ID + 1))]
    assert min(ids) >= MIN_DOMAIN_ID >= 1
    assert max(ids) <= MAX_DOMAIN_ID
    assert all(a != b for a, b in itertools.pairwise(ids))
    # Ids another run on this machine holds are skipped; the rest of the range is used.
    assert len(set(ids)) > (MAX_DOMAIN_ID - MIN_DOMAIN_ID + 1) // 2


def test_a_domain_another_process_holds_is_never_handed_out(tmp_path):
    """Two runs at once (two test suites, a demo beside a test) must not share a domain."""
    import subprocess

    from sphere_twin import processes

    taken = fresh_domain_id()
    processes._held_domains.pop(taken).close()  # let the other process have it
    ready = tmp_path / 'ready'
    holder = subprocess.Popen([sys.executable, '-c', (
        'import sys, time\n'
        'from pathlib import Path\n'
        'from sphere_twin import processes\n'
        f'assert processes._reserve({taken})\n'
        f'Path({str(ready)!r}).touch()\n'
        'time.sleep(30)\n')])
    try:
        deadline = time.monotonic() + 20.0
        while not ready.exists() and time.monotonic() < deadline:
            time.sleep(0.05)
        assert ready.exists()
        ids = [fresh_domain_id() for _ in range(2 * (MAX_DOMAIN_ID - MIN_DOMAIN_ID + 1))]
    finally:
        holder.kill()
        holder.wait()
    assert taken not in ids


def test_parameter_args_are_ros_arguments():
    assert parameter_args() == []
    assert parameter_args(max_messages=20, publish_rate_hz=100.0) == [
        '--ros-args', '-p', 'max_messages:=20', '-p', 'publish_rate_hz:=100.0']


def test_stop_escalates_to_sigterm_when_sigint_is_ignored(ros_nodes):
    child = ros_nodes.start(sys.executable, ['-c', IGNORES_SIGINT_EXITS_ON_SIGTERM])
    child.wait_for_output('ready', READY_TIMEOUT_S)
    assert stop(child, timeout_s=STOP_TIMEOUT_S) == 0
    assert not child.running()


def test_stop_escalates_to_sigkill_as_a_last_resort(ros_nodes):
    child = ros_nodes.start(sys.executable, ['-c', IGNORES_SIGINT_AND_SIGTERM])
    child.wait_for_output('ready', READY_TIMEOUT_S)
    assert stop(child, timeout_s=STOP_TIMEOUT_S) == -signal.SIGKILL
    assert not os.path.exists(f'/proc/{child.pid}')


def test_stop_reaps_an_exited_process_and_keeps_its_output(ros_nodes):
    child = ros_nodes.start(sys.executable, ['-c', 'print("out"); import sys; sys.exit(3)'])
    assert child.wait(READY_TIMEOUT_S) == 3
    assert stop(child) == 3
    assert stop(child) == 3
    assert child.stdout_text() == 'out\n'


@pytest.mark.ros
def test_spawned_nodes_get_localhost_discovery_even_if_the_parent_lacks_it(
        ros_nodes, monkeypatch):
    monkeypatch.delenv(DISCOVERY_RANGE_VAR, raising=False)
    simulator = ros_nodes.start('simulator')
    environ = _environ_of(simulator.pid)
    assert environ[DISCOVERY_RANGE_VAR] == 'LOCALHOST'
    assert environ[DOMAIN_ID_VAR] == str(ros_nodes.domain_id)
    # And the node itself runs with them: its start-up line reports the context's domain.
    simulator.wait_for_output(
        f'{DISCOVERY_RANGE_VAR}=LOCALHOST, domain id {ros_nodes.domain_id}', READY_TIMEOUT_S)
