"""``sphere-twin doctor``: check that this installation can run the twin.

Each check is a function returning ``(ok, detail)``; :data:`CHECKS` lists them in report
order, so a new one (e.g. the physics model's compiled right-hand side) is one more entry.
ROS is probed in a child Python process: a broken RMW can then only fail its check, not
crash the doctor, and the CLI itself never imports rclpy.
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib.metadata
import json
import os
import subprocess
import sys
from collections.abc import Callable, Iterable, Sequence
from typing import Any, TextIO

from sphere_twin.node_runtime.ros_env import (
    DEFAULT_DISCOVERY_RANGE,
    DEFAULT_DOMAIN_ID,
    DISCOVERY_RANGE_VAR,
    DOMAIN_ID_VAR,
)

KEY_PACKAGES = (
    'ros-jazzy-rclpy',
    'ros-jazzy-rmw-fastrtps-cpp',
    'numpy',
    'scipy',
    'numba',
    'mcap',
    'mcap-ros2-support',
)
# rmw accepts domain ids up to 232 (ports beyond that overflow 16 bits).
MAX_DOMAIN_ID = 232
PROBE_TIMEOUT_S = 60.0

_RCLPY_PROBE = 'import os, rclpy; print(os.path.dirname(rclpy.__file__))'
_RMW_PROBE = '''
import rclpy
rclpy.init()
try:
    node = rclpy.create_node('sphere_twin_doctor')
    print(rclpy.get_rmw_implementation_identifier(), node.context.get_domain_id())
    node.destroy_node()
finally:
    rclpy.shutdown()
'''


@dataclasses.dataclass(frozen=True)
class CheckResult:
    """Outcome of one check."""

    name: str
    ok: bool
    detail: str


def _run_probe(code: str) -> tuple[bool, str]:
    """Run ``code`` in a child Python: ``(ok, last line of stdout, or of stderr if it failed)``."""
    try:
        result = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                                timeout=PROBE_TIMEOUT_S, check=False)
    except subprocess.TimeoutExpired:
        return False, f'probe did not finish within {PROBE_TIMEOUT_S:g} s'
    if result.returncode != 0:
        lines = result.stderr.strip().splitlines() or [f'exit code {result.returncode}']
        return False, lines[-1]
    lines = result.stdout.strip().splitlines()
    return True, lines[-1] if lines else ''


def check_rclpy() -> tuple[bool, str]:
    """rclpy imports."""
    ok, detail = _run_probe(_RCLPY_PROBE)
    if not ok:
        return False, f'import rclpy failed: {detail}'
    return True, f'rclpy {_version("ros-jazzy-rclpy") or "(version unknown)"} from {detail}'


def check_rmw() -> tuple[bool, str]:
    """The RMW implementation loads and can create a node (then shuts down)."""
    ok, detail = _run_probe(_RMW_PROBE)
    if not ok:
        return False, f'could not create a node: {detail}'
    identifier, domain_id = detail.split()
    return True, f'{identifier}: created and destroyed a node on domain {domain_id}'


def check_discovery_range() -> tuple[bool, str]:
    """DDS discovery is limited to this machine."""
    value = os.environ.get(DISCOVERY_RANGE_VAR)
    if value == DEFAULT_DISCOVERY_RANGE:
        return True, value
    shown = '(unset)' if value is None else value
    return False, f'{shown}; the twin expects {DEFAULT_DISCOVERY_RANGE}'


def check_domain_id() -> tuple[bool, str]:
    """ROS_DOMAIN_ID is unset or a valid domain id."""
    value = os.environ.get(DOMAIN_ID_VAR)
    if value is None:
        return True, f'(unset, domain {DEFAULT_DOMAIN_ID})'
    if value.strip().isdigit() and int(value) <= MAX_DOMAIN_ID:
        return True, value.strip()
    return False, f'{value!r} is not an integer in 0..{MAX_DOMAIN_ID}'


def check_packages() -> tuple[bool, str]:
    """The key packages are installed."""
    versions = package_versions()
    missing = [name for name, version in versions.items() if version is None]
    if missing:
        return False, 'missing: ' + ', '.join(missing)
    return True, ', '.join(f'{name} {version}' for name, version in versions.items())


def check_numba() -> tuple[bool, str]:
    """numba compiles and runs a function."""
    # Imported here so that a missing or broken numba fails this check instead of the doctor.
    import numba
    import numpy as np

    @numba.njit(cache=False)
    def sum_of_squares(values):  # type: ignore[no-untyped-def]  # numba types it from its call
        total = 0.0
        for value in values:
            total += value * value
        return total

    values = np.arange(1.0, 11.0)
    result = sum_of_squares(values)
    expected = 385.0
    if result != expected:
        return False, f'compiled sum of squares 1..10 gave {result}, expected {expected:g}'
    return True, f'numba {numba.__version__}: compiled and ran (sum of squares 1..10 = {result:g})'


CHECKS = (
    ('rclpy', check_rclpy),
    ('rmw', check_rmw),
    ('discovery_range', check_discovery_range),
    ('domain_id', check_domain_id),
    ('packages', check_packages),
    ('numba', check_numba),
)


def _version(distribution: str) -> str | None:
    try:
        return importlib.metadata.version(distribution)
    except importlib.metadata.PackageNotFoundError:
        return None


def package_versions(names: Iterable[str] = KEY_PACKAGES) -> dict[str, str | None]:
    """Installed version of each distribution, None where missing."""
    return {name: _version(name) for name in names}


def run_checks(checks: Iterable[tuple[str, Callable[[], tuple[bool, str]]]] = CHECKS,
               ) -> list[CheckResult]:
    """Run ``checks`` (pairs of name and function); an exception fails its check only."""
    results: list[CheckResult] = []
    for name, check in checks:
        try:
            ok, detail = check()
        except Exception as error:  # a check that raises has failed, the others still run
            ok, detail = False, f'{type(error).__name__}: {error}'
        results.append(CheckResult(name, bool(ok), str(detail)))
    return results


def summary(results: Sequence[CheckResult]) -> str:
    """The final line: all passed, or which checks failed and why."""
    failed = [r for r in results if not r.ok]
    if not failed:
        return f'doctor: all {len(results)} checks passed'
    reasons = '; '.join(f'{r.name} ({r.detail})' for r in failed)
    return f'doctor: {len(failed)} of {len(results)} checks failed: {reasons}'


def report(results: Sequence[CheckResult]) -> dict[str, Any]:
    """The JSON document of ``--json``."""
    return {
        'ok': all(r.ok for r in results),
        'summary': summary(results),
        'checks': [dataclasses.asdict(r) for r in results],
        'environment': {
            DISCOVERY_RANGE_VAR: os.environ.get(DISCOVERY_RANGE_VAR),
            DOMAIN_ID_VAR: os.environ.get(DOMAIN_ID_VAR),
        },
        'versions': package_versions(),
    }


def doctor(checks: Iterable[tuple[str, Callable[[], tuple[bool, str]]]] = CHECKS,
           as_json: bool = False, out: TextIO | None = None) -> int:
    """Run the checks, print the report, return the exit code.

    Parameters
    ----------
    checks : sequence of (str, callable)
        Named functions returning ``(ok, detail)``.
    as_json : bool
        Print one JSON document instead of one line per check and a summary line.
    out : file-like, optional
        Where to print; ``sys.stdout`` by default.

    Returns
    -------
    int
        0 if every check passed, 1 otherwise.
    """
    out = sys.stdout if out is None else out
    results = run_checks(checks)
    if as_json:
        print(json.dumps(report(results), indent=2), file=out)
    else:
        width = max(len(r.name) for r in results)
        for result in results:
            print(f'{"ok" if result.ok else "FAIL":4}  {result.name:{width}}  {result.detail}',
                  file=out)
        print(summary(results), file=out)
    return 0 if all(r.ok for r in results) else 1


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add the ``doctor`` subcommand to the ``sphere-twin`` parser."""
    parser = subparsers.add_parser(
        'doctor', help='check that ROS 2, the RMW and the compiled parts work here',
        description='Check rclpy, the RMW implementation, the discovery range, the domain id, '
                    'package versions and numba; exit 0 only if every check passes.')
    parser.add_argument('--json', action='store_true', help='print one JSON document')
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Entry point of the subcommand; returns the exit code."""
    return doctor(as_json=args.json)
