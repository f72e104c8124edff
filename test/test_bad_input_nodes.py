"""Every node refuses a user's mistake at start-up with one line, ``<node>: error: ...``, and
exit status 2: a params file it cannot read, a parameter it does not have, a value out of its
range or not among its choices, a file or bag that is not there. No traceback, no hang, no
silent wrong result.

``{tmp}`` in an argument is the test's temporary directory (its files are made by
:func:`bad_files`). test_node_startup.py's BAD_STARTS holds the older cases.
"""

import pytest

from sphere_twin.processes import parameter_args

pytestmark = pytest.mark.ros

EXIT_TIMEOUT_S = 60.0

NOT_YAML = 'simulator: [ros__parameters\n'
NEGATIVE_BEAM_MASS = 'base: calibrated\noverrides: {beam.mass_kg: -1.0}\n'


def _p(**parameters: object) -> list[str]:
    return parameter_args(**parameters)


# (case id, executable, arguments, what the one line says)
BAD_INPUTS = [
    ('params-file-not-yaml', 'simulator', ['--ros-args', '--params-file', '{tmp}/bad.yaml'],
     'cannot read --params-file {tmp}/bad.yaml: '),
    ('params-file-missing', 'simulator', ['--ros-args', '--params-file', '{tmp}/none.yaml'],
     'cannot read --params-file {tmp}/none.yaml: no such file'),
    ('unknown-parameter', 'simulator', _p(plant_kind='x'),
     'unknown parameter plant_kind (did you mean plant?); the simulator takes: plant, fidelity, '
     'scene'),
    ('negative-beam-mass', 'simulator',
     _p(plant='continuous', params='{tmp}/negative_mass.yaml'), 'mass_kg'),
    ('integer-not-a-number', 'simulator', _p(seed='abc'),
     "parameter seed must be an integer, got 'abc'"),
    ('malformed-p', 'monitor', ['--ros-args', '-p', 'max_messages'],
     "invalid ROS arguments: Couldn't parse parameter override rule"),
    ('controller-out-of-range', 'controller', _p(phi_min_deg=-1.0),
     'parameter phi_min_deg = -1 is outside [0, 10]'),
    ('controller-unknown', 'controller', _p(kick_period=0.04),
     'unknown parameter kick_period (did you mean kick_period_s?)'),
    ('setpoint-outside-unit-disk', 'reference', _p(setpoint_xy=[2.0, 2.0]),
     'parameter setpoint_xy = [2.0, 2.0] is not the x-y part of a unit normal: '
     '|(x, y)| = 2.828 must be below 1'),
    ('not-finite', 'reference', _p(amplitude='nan'),
     'parameter amplitude = nan is not finite: give a finite number in [0, 1]'),
    ('chunk-size', 'recorder', _p(chunk_size_bytes=-1, output_dir='{tmp}/bag1'),
     'parameter chunk_size_bytes = -1 is outside [1024, 2147483647]'),
    ('compression', 'recorder', _p(compression='gzip', output_dir='{tmp}/bag2'),
     "parameter compression = 'gzip' is not one of: zstd, lz4, none"),
    ('output-dir-not-empty', 'recorder', _p(output_dir='{tmp}'),
     'parameter output_dir: bag directory {tmp} already exists and is not empty'),
    ('output-dir-under-a-file', 'recorder', _p(output_dir='{tmp}/bad.yaml/bag'),
     'cannot create output_dir {tmp}/bad.yaml/bag: Not a directory'),
    ('topic-outside-contract', 'recorder', _p(topics=['/nope'], output_dir='{tmp}/bag3'),
     "parameter topics: no topic '/nope' in the contract; known: /sphere/surface_normal"),
    ('offset-beyond-end', 'player', _p(bag='example', start_offset_s=1e9),
     'parameter start_offset_s = 1e+09 is beyond the end of '),
    ('rate-zero', 'player', _p(bag='example', rate=0),
     'parameter rate = 0 is outside [0.001, 1000]'),
    ('topic-not-in-bag', 'player', _p(bag='example', topics=['/nope']),
     'parameter topics: /nope not in '),
    ('no-bag', 'player', _p(bag='{tmp}/no_bag'), 'is not a bag'),
    ('monitor-out-of-range', 'monitor', _p(max_messages=-1),
     'parameter max_messages = -1 is outside [0, 2147483647]'),
    ('monitor-unknown', 'monitor', _p(max_message=5),
     'unknown parameter max_message (did you mean max_messages?); the monitor takes: '
     'max_messages'),
]


@pytest.fixture
def bad_files(tmp_path):
    """The files the cases name: a params file that is not YAML, a parameter set with a
    negative beam mass; the directory itself is not empty."""
    (tmp_path / 'bad.yaml').write_text(NOT_YAML)
    (tmp_path / 'negative_mass.yaml').write_text(NEGATIVE_BEAM_MASS)
    return tmp_path


@pytest.mark.parametrize(('executable', 'args', 'says'),
                         [case[1:] for case in BAD_INPUTS], ids=[case[0] for case in BAD_INPUTS])
def test_bad_input_to_a_node_is_one_line_and_exit_status_2(ros_nodes, bad_files, executable,
                                                             args, says):
    node = ros_nodes.start(executable, [a.replace('{tmp}', str(bad_files)) for a in args])
    assert node.wait(EXIT_TIMEOUT_S) == 2
    err = node.stderr_text()
    assert 'Traceback' not in err, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f'{executable}: error: '), err
    assert says.replace('{tmp}', str(bad_files)) in lines[0], err


def test_the_six_nodes_are_all_asked():
    assert {case[1] for case in BAD_INPUTS} == {
        'simulator', 'controller', 'reference', 'recorder', 'player', 'monitor'}


# --- what is not a mistake, in-process ----------------------------------------------------

OTHER_NODES_AND_SIM_TIME = """\
/**:
  ros__parameters:
    use_sim_time: true
simulator:
  ros__parameters:
    plant: continuous
reference:
  ros__parameters:
    setpoint_xy: [0, 0]
"""


def test_a_params_file_may_hold_other_nodes_sections_and_rclpys_parameters(tmp_path,
                                                                              monkeypatch):
    """Only this node's overrides are checked: the simulator's section is not the reference's,
    use_sim_time is rclpy's own, and integers are taken for doubles."""
    import rclpy

    from sphere_twin.nodes.reference_node import ReferenceNode
    from sphere_twin.processes import fresh_domain_id

    monkeypatch.setenv('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    params_file = tmp_path / 'twin.yaml'
    params_file.write_text(OTHER_NODES_AND_SIM_TIME)
    context = rclpy.Context()
    rclpy.init(args=['reference', '--ros-args', '--params-file', str(params_file)],
               context=context, domain_id=fresh_domain_id())
    try:
        node = ReferenceNode(context=context)
        assert node.schedule.setpoint.xy == (0.0, 0.0)
        assert node.get_parameter('use_sim_time').value is True
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)


def test_bad_input_rcl_refusals_become_one_line(tmp_path):
    from sphere_twin.node_runtime.ros_env import ros_arguments_error_line

    present = tmp_path / 'p.yaml'
    present.write_text(NOT_YAML)
    refused = RuntimeError(
        "failed to initialize rcl: Couldn't parse params file: '--params-file "
        f"{present}'. Error: Sequences can only be values and not keys in params. Error at "
        'line 1\n, at /project/src/parse.c:841, at /project/src/rcl/arguments.c:415')
    assert ros_arguments_error_line('controller', refused) == (
        f'controller: error: cannot read --params-file {present}: Sequences can only be values '
        'and not keys in params. Error at line 1 (a YAML file of <node>: {ros__parameters: '
        '{name: value}} sections)')
    trailing = RuntimeError("failed to initialize rcl: Couldn't parse trailing --params-file "
                            'flag. No file path provided., at /project/src/rcl/arguments.c:419')
    assert ros_arguments_error_line('monitor', trailing) == (
        "monitor: error: invalid ROS arguments: Couldn't parse trailing --params-file flag. No "
        'file path provided. (parameters are given as --ros-args -p name:=value)')
