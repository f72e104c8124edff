"""Every node's parameters are written once, in sphere_twin/nodes/parameters.py: the nodes
declare exactly those, and config/twin.yaml, the arguments of launch/twin.launch.py and the
code that takes a choice-valued parameter agree with them. Checked without the `launch`
packages (not on PyPI)."""

import math
from pathlib import Path

import pytest
import yaml

from sphere_twin.node_runtime.parameter_specs import ParameterSpec, ParameterType
from sphere_twin.nodes import parameters
from sphere_twin.nodes.parameters import NODE_PARAMETERS

ROOT = Path(__file__).resolve().parents[1]
LAUNCH_FILE = ROOT / 'launch' / 'twin.launch.py'
CONFIG_FILE = ROOT / 'config' / 'twin.yaml'

# Where config/twin.yaml sets a value other than the node's default, on purpose:
# (node, parameter) -> value. The launch file passes no value unless its argument is given
# (but use_sim_time, below).
INTENDED_DIFFERENCES = {
    # The example bag; started alone, the player requires a bag.
    ('player', 'bag'): 'example',
}
# Parameters that rclpy declares on every node; the params file and the launch file may set
# them too: name -> the value config/twin.yaml gives, by node.
ROS_PARAMETERS = {'use_sim_time': {'reference': True, 'controller': True}}
# The type the launch file converts an argument to for each parameter type.
LAUNCH_VALUE_TYPES = {ParameterType.BOOL: 'bool', ParameterType.INTEGER: 'int',
                      ParameterType.DOUBLE: 'float', ParameterType.STRING: 'str'}


def _specs(node):
    return {spec.name: spec for spec in NODE_PARAMETERS[node]}


def _choice_parameters():
    """(node, parameter) -> what the code that takes the value accepts."""
    from sphere_control.controllers import CONTROLLER_KINDS
    from sphere_sim.model.fidelity import LADDER
    from sphere_sim.twin.plant_setup import PLANT_KINDS
    from sphere_twin.bag.writer import COMPRESSIONS

    # '' leaves each of the two to the other (plant_and_fidelity).
    return {('simulator', 'plant'): ('', *PLANT_KINDS),
            ('simulator', 'fidelity'): ('', *LADDER),
            ('controller', 'controller'): tuple(CONTROLLER_KINDS),
            ('recorder', 'compression'): tuple(COMPRESSIONS)}


def _has_type(spec: ParameterSpec, value):
    """Whether a node takes ``value`` for ``spec`` (a double also takes an integer)."""
    number = isinstance(value, int | float) and not isinstance(value, bool)
    array = isinstance(value, list | tuple)
    return {ParameterType.BOOL: isinstance(value, bool),
            ParameterType.INTEGER: number and isinstance(value, int),
            ParameterType.DOUBLE: number,
            ParameterType.STRING: isinstance(value, str),
            ParameterType.DOUBLE_ARRAY: array and all(isinstance(v, float) for v in value),
            ParameterType.STRING_ARRAY: array and all(isinstance(v, str) for v in value),
            }[spec.type]


def _allowed(spec: ParameterSpec, value):
    if spec.range is not None and not spec.range[0] <= value <= spec.range[1]:
        return False
    return spec.choices is None or value in spec.choices


def _same(a, b):
    if isinstance(a, list | tuple) and isinstance(b, list | tuple):
        return list(a) == list(b)
    return type(a) is type(b) and a == b


def _expected(node, spec):
    """The value a node gets from config/twin.yaml or the launch file's default."""
    return INTENDED_DIFFERENCES.get((node, spec.name), spec.default)


def _config():
    return {node: section['ros__parameters']
            for node, section in yaml.safe_load(CONFIG_FILE.read_text()).items()}


# --- the specs themselves ---------------------------------------------------------------

# What `ros2 param set` may change while a node runs: each node applies it at once
# (test_nodes_in_process); everything else builds the node and is read once.
SETTABLE_AT_RUN_TIME = {('simulator', 'publish_rate_hz'), ('simulator', 'real_time_factor'),
                        ('simulator', 'noise_std_rad'), ('controller', 'preview'),
                        ('reference', 'publish_rate_hz')}

@pytest.mark.parametrize('node', sorted(NODE_PARAMETERS))
def test_every_default_has_its_type_and_lies_in_its_range(node):
    names = [spec.name for spec in NODE_PARAMETERS[node]]
    assert len(names) == len(set(names))
    for spec in NODE_PARAMETERS[node]:
        assert spec.description
        assert spec.read_only == ((node, spec.name) not in SETTABLE_AT_RUN_TIME), spec.name
        assert spec.fixed_because
        if spec.default is None:  # declared by type alone
            assert spec.type in (ParameterType.STRING_ARRAY, ParameterType.DOUBLE_ARRAY)
            continue
        assert _has_type(spec, spec.default), spec.name
        assert _allowed(spec, spec.default), spec.name
        assert spec.range is None or spec.type in (ParameterType.INTEGER, ParameterType.DOUBLE)


def test_choice_valued_parameters_offer_exactly_what_the_code_accepts():
    accepted = _choice_parameters()
    marked = {(node, spec.name): spec.choices for node, specs in NODE_PARAMETERS.items()
              for spec in specs if spec.choices is not None}
    assert marked == accepted
    for (node, name), choices in accepted.items():
        spec = _specs(node)[name]
        for choice in choices:
            assert choice in spec.description
        assert spec.default in choices


def test_constants_written_out_to_keep_the_nodes_light_match_their_source():
    from sphere_control.controllers import DEFAULT_PHI_MIN_RAD
    from sphere_twin.bag.writer import DEFAULT_CHUNK_SIZE_BYTES

    assert math.degrees(DEFAULT_PHI_MIN_RAD) == parameters.DEFAULT_PHI_MIN_DEG
    assert parameters.DEFAULT_CHUNK_SIZE_BYTES == DEFAULT_CHUNK_SIZE_BYTES


# --- config/twin.yaml -------------------------------------------------------------------

def test_the_config_has_a_section_for_each_launched_node():
    assert set(_config()) == set(NODE_PARAMETERS) - {'monitor'}


@pytest.mark.parametrize('node', sorted(set(NODE_PARAMETERS) - {'monitor'}))
def test_the_config_sets_declared_parameters_to_their_defaults(node):
    config = _config()[node]
    specs = _specs(node)
    ros = {name: values[node] for name, values in ROS_PARAMETERS.items() if node in values}
    assert set(config) <= set(specs) | set(ROS_PARAMETERS)
    assert {name: config[name] for name in set(config) & set(ROS_PARAMETERS)} == ros
    for name, value in config.items():
        if name in ROS_PARAMETERS:
            continue
        spec = specs[name]
        assert _has_type(spec, value), f'{node}.{name}: {value!r} is not a {spec.type.value}'
        assert _allowed(spec, value), f'{node}.{name}: {value!r} is out of range'
        assert _same(value, _expected(node, spec)), (
            f'{node}.{name} = {value!r} in {CONFIG_FILE.name}, but the node\'s default is '
            f'{spec.default!r}: change one, or name the difference in INTENDED_DIFFERENCES')


def test_every_intended_difference_is_in_the_config_and_differs():
    config = _config()
    for (node, name), value in INTENDED_DIFFERENCES.items():
        assert config[node][name] == value
        assert not _same(value, _specs(node)[name].default)


# --- launch/twin.launch.py --------------------------------------------------------------

def _launch_file():
    namespace = {}
    exec(compile(LAUNCH_FILE.read_text(), str(LAUNCH_FILE), 'exec'), namespace)
    return namespace


def test_launch_arguments_passed_to_nodes_agree_with_their_declarations():
    launch = _launch_file()
    arguments, passed = launch['ARGUMENTS'], launch['PARAMETER_ARGUMENTS']
    takers = {node for _, nodes in passed.values() for node in nodes}
    assert takers >= {'simulator', 'controller', 'reference', 'recorder', 'player'}
    for name, (value_type, nodes) in passed.items():
        default, description = arguments[name]
        if name in ROS_PARAMETERS:
            # use_sim_time: true for the nodes on the clock, whatever the params file says.
            assert value_type == 'bool' and default == 'true', f'launch argument {name}'
            assert set(nodes) == {*ROS_PARAMETERS[name], 'rviz2'}
            continue
        # "Not given": the node keeps the params file's value, and the argument says so.
        assert default == launch['NOT_GIVEN'] == '', f'launch argument {name}'
        assert launch['_FROM_FILE'] in description, f'launch argument {name}'
        for node in nodes:
            specs = _specs(node)
            assert name in specs, f'the launch file passes {name} to {node}, which lacks it'
            spec = specs[name]
            assert value_type == LAUNCH_VALUE_TYPES[spec.type], f'{node}.{name}'
            assert description == spec.description + launch['_FROM_FILE'], name


def test_no_launch_argument_default_overrides_the_params_file_but_sim_time():
    """With every argument at its default a node gets only the params file, but for the
    nodes on the clock use_sim_time: true (a params file without their sections would
    otherwise put them on the wall clock)."""
    launch = _launch_file()
    defaults = {name: default for name, (default, _) in launch['ARGUMENTS'].items()
                if default is not None}
    for play in ('false', 'true'):
        for node, given in launch['node_parameters'](
                defaults | {'play': play, 'record': 'true'}).items():
            expected = {'use_sim_time': True} if node in ROS_PARAMETERS['use_sim_time'] else {}
            assert given == expected, f'{node} gets {given} with every argument at its default'


def test_a_given_launch_argument_reaches_the_node_as_its_parameter_type():
    """Every argument, given as ``ros2 launch`` gives it (text), is passed to each node that
    takes it with the value the node's parameter type needs."""
    launch = _launch_file()
    samples = {ParameterType.BOOL: ('false', False), ParameterType.INTEGER: ('7', 7),
               ParameterType.DOUBLE: ('2', 2.0), ParameterType.STRING: ('2', '2')}
    for name, (_, nodes) in launch['PARAMETER_ARGUMENTS'].items():
        for node in nodes:
            if node == 'rviz2':
                continue
            kind = ParameterType.BOOL if name in ROS_PARAMETERS else _specs(node)[name].type
            text, value = samples[kind]
            play = 'true' if node == 'player' else 'false'
            given = launch['node_parameters']({name: text, 'play': play, 'record': 'true'})
            assert _same(given[node][name], value), f'{name}:={text} to {node}'
            on_clock = {'use_sim_time'} if node in ROS_PARAMETERS['use_sim_time'] else set()
            assert set(given[node]) == {name} | on_clock


# --- the nodes declare exactly the specs --------------------------------------------------

def _build(node, context, tmp_path):
    from rclpy.parameter import Parameter

    from sphere_twin.nodes.controller_node import ControllerNode
    from sphere_twin.nodes.monitor_node import MonitorNode
    from sphere_twin.nodes.player_node import PlayerNode
    from sphere_twin.nodes.recorder_node import RecorderNode
    from sphere_twin.nodes.reference_node import ReferenceNode
    from sphere_twin.nodes.simulator_node import SimulatorNode

    if node == 'simulator':  # a plant of its own: the parameters are what is checked
        return SimulatorNode(plant=object(), context=context), set()
    if node == 'recorder':
        return RecorderNode(context=context, parameter_overrides=[
            Parameter('output_dir', value=str(tmp_path / 'bag'))]), {'output_dir'}
    if node == 'player':
        return PlayerNode(context=context, parameter_overrides=[
            Parameter('bag', value='example')]), {'bag'}
    cls = {'controller': ControllerNode, 'reference': ReferenceNode, 'monitor': MonitorNode}
    return cls[node](context=context), set()


@pytest.mark.ros
@pytest.mark.parametrize('node', sorted(NODE_PARAMETERS))
def test_each_node_declares_its_specs(node, context, tmp_path, monkeypatch):
    from rclpy.node import Node

    monkeypatch.chdir(tmp_path)
    bare = Node('bare', context=context)
    builtin = set(bare.list_parameters([], 0).names)
    bare.destroy_node()
    built, overridden = _build(node, context, tmp_path)
    try:
        specs = _specs(node)
        assert set(built.list_parameters([], 0).names) - builtin == set(specs)
        for name, spec in specs.items():
            descriptor = built.describe_parameter(name)
            assert descriptor.description == spec.description
            assert descriptor.read_only == spec.read_only
            floats = [(r.from_value, r.to_value) for r in descriptor.floating_point_range]
            ints = [(r.from_value, r.to_value) for r in descriptor.integer_range]
            assert floats == ([spec.range] if spec.type is ParameterType.DOUBLE
                              and spec.range is not None else [])
            assert ints == ([spec.range] if spec.type is ParameterType.INTEGER
                            and spec.range is not None else [])
            if name not in overridden and spec.default is not None:  # else uninitialised
                assert _same(built.get_parameter(name).value, spec.default), name
    finally:
        built.destroy_node()


@pytest.mark.parametrize('executable', sorted(NODE_PARAMETERS))
def test_every_executable_prints_its_parameters_with_help_and_starts_nothing(executable):
    import subprocess

    from sphere_twin.processes import child_environment, fresh_domain_id, resolve_executable

    result = subprocess.run([resolve_executable(executable), '--help'], capture_output=True,
                            text=True, timeout=60, check=False,
                            env=child_environment(fresh_domain_id()))
    assert result.returncode == 0, result.stderr
    assert result.stderr == ''
    lines = result.stdout.splitlines()
    assert lines[0].startswith(f'usage: {executable} [--ros-args -p NAME:=VALUE')
    listed = [line.split()[0] for line in lines if line.startswith('  ') and
              not line.startswith('      ')]
    assert listed == [spec.name for spec in NODE_PARAMETERS[executable]]
