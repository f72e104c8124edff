"""``sphere-twin doctor``: the checks, the report, and the installed command."""

import importlib.metadata
import io
import json
import os
import subprocess

import pytest

from sphere_twin.commands import doctor
from sphere_twin.node_runtime.ros_env import DISCOVERY_RANGE_VAR, DOMAIN_ID_VAR
from sphere_twin.processes import fresh_domain_id, resolve_executable

CLI_TIMEOUT_S = 120.0


def _passing():
    return True, 'fine'


def _missing_library():
    return False, 'libfoo.so not found'


def _raising():
    raise ImportError("No module named 'numba'")


def _run(checks, as_json=False):
    out = io.StringIO()
    code = doctor.doctor(checks=checks, as_json=as_json, out=out)
    return code, out.getvalue().splitlines()


def test_all_passing_checks_exit_0_with_one_line_each():
    code, lines = _run((('first', _passing), ('second', _passing)))
    assert code == 0
    assert lines == ['ok    first   fine', 'ok    second  fine', 'doctor: all 2 checks passed']


def test_a_failing_check_exits_nonzero_with_a_one_line_reason_naming_it():
    code, lines = _run((('first', _passing), ('rmw', _missing_library), ('numba', _raising)))
    assert code == 1
    assert lines[1] == 'FAIL  rmw    libfoo.so not found'
    assert lines[2] == "FAIL  numba  ImportError: No module named 'numba'"
    assert lines[-1] == ("doctor: 2 of 3 checks failed: rmw (libfoo.so not found); "
                         "numba (ImportError: No module named 'numba')")
    assert len(lines) == 4


def test_json_report_carries_checks_environment_and_versions(monkeypatch):
    monkeypatch.setenv(DISCOVERY_RANGE_VAR, 'LOCALHOST')
    monkeypatch.setenv(DOMAIN_ID_VAR, '17')
    code, lines = _run((('first', _passing), ('rmw', _missing_library)), as_json=True)
    report = json.loads('\n'.join(lines))
    assert code == 1
    assert report['ok'] is False
    assert report['checks'][1] == {'name': 'rmw', 'ok': False, 'detail': 'libfoo.so not found'}
    assert report['environment'] == {DISCOVERY_RANGE_VAR: 'LOCALHOST', DOMAIN_ID_VAR: '17'}
    assert report['versions']['numpy'] == importlib.metadata.version('numpy')


@pytest.mark.parametrize(('value', 'ok'), [
    ('LOCALHOST', True), ('SUBNET', False), ('OFF', False), (None, False)])
def test_discovery_range_check_accepts_only_localhost(monkeypatch, value, ok):
    if value is None:
        monkeypatch.delenv(DISCOVERY_RANGE_VAR, raising=False)
    else:
        monkeypatch.setenv(DISCOVERY_RANGE_VAR, value)
    assert doctor.check_discovery_range()[0] is ok


@pytest.mark.parametrize(('value', 'ok'), [
    (None, True), ('0', True), ('42', True), ('232', True), ('233', False), ('x', False),
    ('-1', False)])
def test_domain_id_check(monkeypatch, value, ok):
    if value is None:
        monkeypatch.delenv(DOMAIN_ID_VAR, raising=False)
    else:
        monkeypatch.setenv(DOMAIN_ID_VAR, value)
    assert doctor.check_domain_id()[0] is ok


def test_package_check_names_what_is_missing(monkeypatch):
    assert doctor.package_versions(('numpy', 'no-such-distribution-xyz')) == {
        'numpy': importlib.metadata.version('numpy'), 'no-such-distribution-xyz': None}
    monkeypatch.setattr(doctor, 'package_versions', lambda: {'numpy': '2', 'mcap': None})
    assert doctor.check_packages() == (False, 'missing: mcap')


def test_numba_check_compiles_and_runs():
    ok, detail = doctor.check_numba()
    assert ok
    assert '385' in detail


@pytest.fixture(scope='module')
def doctor_json_without_discovery_range():
    """``sphere-twin doctor --json`` run as a process whose environment lacks the range."""
    env = {k: v for k, v in os.environ.items() if k != DISCOVERY_RANGE_VAR}
    env[DOMAIN_ID_VAR] = str(fresh_domain_id())
    result = subprocess.run([resolve_executable('sphere-twin'), 'doctor', '--json'], env=env,
                            capture_output=True, text=True, timeout=CLI_TIMEOUT_S, check=False)
    return result, env[DOMAIN_ID_VAR]


@pytest.mark.ros
def test_installed_doctor_passes_here_and_reports_every_field(
        doctor_json_without_discovery_range):
    result, domain_id = doctor_json_without_discovery_range
    assert result.returncode == 0, result.stdout + result.stderr
    report = json.loads(result.stdout)
    checks = {check['name']: check for check in report['checks']}
    assert list(checks) == [name for name, _ in doctor.CHECKS]
    assert all(check['ok'] for check in checks.values())
    assert checks['rmw']['detail'] == (
        f'rmw_fastrtps_cpp: created and destroyed a node on domain {domain_id}')
    assert report['versions'] == doctor.package_versions()
    assert report['summary'] == f'doctor: all {len(doctor.CHECKS)} checks passed'


@pytest.mark.ros
def test_installed_doctor_sets_localhost_when_the_environment_lacks_it(
        doctor_json_without_discovery_range):
    result, _ = doctor_json_without_discovery_range
    report = json.loads(result.stdout)
    assert report['environment'][DISCOVERY_RANGE_VAR] == 'LOCALHOST'
    assert {'name': 'discovery_range', 'ok': True, 'detail': 'LOCALHOST'} in report['checks']
