"""A node that cannot start says why in one line and exits with 2; a ROS user's ordinary
parameters (an integer where a float is declared) are accepted."""

import pytest

from msg_defs.topics import SURFACE_NORMAL
from sphere_twin.monitor_summary import parse_summaries
from sphere_twin.node_runtime.ros_env import startup_error_line
from sphere_twin.processes import parameter_args

pytestmark = pytest.mark.ros

EXIT_TIMEOUT_S = 60.0

BAD_STARTS = [
    ('simulator', dict(plant='foo'),
     'parameter plant = \'foo\' is not one of: "", continuous, discrete'),
    ('simulator', dict(fidelity='fastest'),
     'parameter fidelity = \'fastest\' is not one of: "", full, sliding, table'),
    ('simulator', dict(plant='discrete', fidelity='sliding'),
     "fidelity 'sliding' is served by the continuous plant, not the discrete one"),
    ('simulator', dict(scene='no_such_scene'), 'no_such_scene'),
    ('simulator', dict(tables=['/nonexistent/table.npz']), '/nonexistent/table.npz'),
    ('simulator', dict(publish_rate_hz=0.5),
     'parameter publish_rate_hz = 0.5 is outside [1, 1000]'),
    ('simulator', dict(publish_rate_hz='fast'), 'parameter publish_rate_hz must be a number'),
    ('simulator', dict(use_sim_time=True), 'the simulator is the clock'),
    ('controller', dict(controller='pid'), "parameter controller = 'pid' is not one of: basic"),
    ('controller', dict(tables=['/nonexistent/table.npz']), '/nonexistent/table.npz'),
    ('reference', dict(setpoint_xy=[0.1]), 'setpoint_xy needs 2 values'),
    ('reference', dict(publish_rate_hz=0), 'parameter publish_rate_hz = 0 is outside'),
]


@pytest.mark.parametrize(('executable', 'parameters', 'says'), BAD_STARTS,
                         ids=[f'{e}-{next(iter(p))}' for e, p, _ in BAD_STARTS])
def test_bad_input_at_start_is_one_line_and_exit_status_2(ros_nodes, executable, parameters, says):
    node = ros_nodes.start(executable, parameter_args(**parameters))
    assert node.wait(EXIT_TIMEOUT_S) == 2
    err = node.stderr_text()
    assert 'Traceback' not in err
    lines = [line for line in err.splitlines() if line.startswith(f'{executable}: error: ')]
    assert len(lines) == 1 and says in lines[0], err


def test_an_integer_is_accepted_where_a_float_is_declared(ros_nodes):
    ros_nodes.start('simulator', parameter_args(publish_rate_hz=100, real_time_factor=2))
    monitor = ros_nodes.start('monitor', parameter_args(max_messages=5))
    assert monitor.wait(EXIT_TIMEOUT_S) == 0
    assert parse_summaries(monitor.stdout_text()) == {SURFACE_NORMAL.name: 5}


def test_a_missing_module_names_what_to_install():
    line = startup_error_line('simulator', ModuleNotFoundError("No module named 'scipy'",
                                                               name='scipy'))
    assert line.startswith('simulator: error: ') and 'python3-scipy' in line
    assert 'rosdep install' in line
