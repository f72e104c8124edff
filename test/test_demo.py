"""``sphere-twin demo``: passes when messages cross between processes, fails when none do."""

import io
import re

import pytest

from sphere_twin.cli import build_parser
from sphere_twin.commands.demo import run_demo
from sphere_twin.processes import NodeSpec

pytestmark = pytest.mark.ros


def _demo(**kwargs):
    out = io.StringIO()
    code = run_demo(out=out, **kwargs)
    return code, out.getvalue().splitlines()


def test_demo_reports_messages_crossing_and_clean_exits():
    code, lines = _demo(duration_s=6.0)
    assert code == 0, '\n'.join(lines)
    started = [line for line in lines if line.startswith('demo: started')]
    assert [line.split()[2] for line in started] == ['simulator', 'monitor']
    assert 'demo: stopped monitor' in '\n'.join(lines)
    assert all(line.endswith('exit code 0') for line in lines if line.startswith('demo: stopped'))
    match = re.match(r'demo: OK: (\d+) messages on /sphere/surface_normal crossed', lines[-1])
    assert match, lines[-1]
    # 50 Hz for 6 s less start-up and discovery: well above zero, at most all of them.
    assert 20 <= int(match.group(1)) <= 300


def test_demo_fails_when_no_messages_cross():
    code, lines = _demo(duration_s=1.0, nodes=(NodeSpec('simulator'),))
    assert code == 1
    assert lines[-1] == 'demo: FAILED: no messages crossed on /sphere/surface_normal'


def test_cli_parses_demo_duration_and_rejects_non_positive():
    parser = build_parser()
    assert parser.parse_args(['demo', '--duration-s', '2.5']).duration_s == 2.5
    assert parser.parse_args(['demo']).duration_s == 5.0
    with pytest.raises(SystemExit):
        parser.parse_args(['demo', '--duration-s', '0'])
