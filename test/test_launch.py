"""launch/twin.launch.py, rviz/twin.rviz, config/twin.yaml and package.xml. The launch file's
rules (which nodes start, which parameters each gets on top of the params file, what stops it
before any node starts) are plain functions checked here without the `launch` package (not on
PyPI); where `launch` and `launch_ros` are installed, the launch description itself is run
through them too."""

import ast
import re
import sys
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest
import yaml

ROOT = Path(__file__).resolve().parents[1]
LAUNCH_FILE = ROOT / 'launch' / 'twin.launch.py'
CONFIG_FILE = ROOT / 'config' / 'twin.yaml'
RVIZ_FILE = ROOT / 'rviz' / 'twin.rviz'
# The functions that import `launch`, reached only through generate_launch_description.
LAUNCH_FUNCTIONS = {'generate_launch_description', '_node_actions'}
TWIN = ['simulator', 'reference', 'controller']


def _tree():
    return ast.parse(LAUNCH_FILE.read_text())


def _launch_file(monkeypatch=None):
    """The launch file's namespace; with ``monkeypatch``, importing `launch` or `launch_ros`
    from it fails, as where they are not installed."""
    if monkeypatch is not None:
        for name in ('launch', 'launch_ros'):
            monkeypatch.setitem(sys.modules, name, None)
    namespace = {}
    exec(compile(_tree(), str(LAUNCH_FILE), 'exec'), namespace)  # defines, imports nothing
    return namespace


def _console_scripts():
    text = (ROOT / 'setup.py').read_text()
    return set(re.findall(r"'([\w-]+) = [\w.]+:\w+'", text))


def _every_argument_given():
    """A configuration giving every argument that sets a node parameter a valid value."""
    samples = {'bool': 'true', 'int': '1', 'float': '0.5'}
    launch = _launch_file()
    return {name: samples.get(kind, 'x') for name, (kind, _) in
            launch['PARAMETER_ARGUMENTS'].items()}


def _declared(executable, ros_context, tmp_path):
    """Parameter names the node declares, built in this process on ``ros_context``."""
    from rclpy.parameter import Parameter

    from sphere_twin.nodes.controller_node import ControllerNode
    from sphere_twin.nodes.player_node import PlayerNode
    from sphere_twin.nodes.recorder_node import RecorderNode
    from sphere_twin.nodes.reference_node import ReferenceNode
    from sphere_twin.nodes.simulator_node import SimulatorNode

    classes = {'simulator': (SimulatorNode, []), 'controller': (ControllerNode, []),
               'reference': (ReferenceNode, []),
               'recorder': (RecorderNode, [Parameter('output_dir', value=str(tmp_path / 'b'))]),
               'player': (PlayerNode, [])}
    cls, overrides = classes[executable]
    node = cls(context=ros_context, parameter_overrides=overrides)
    try:
        return node, set(node.list_parameters([], 0).names)
    finally:
        node.destroy_node()


def test_the_launch_file_imports_launch_only_inside_generate_launch_description(monkeypatch):
    tree = _tree()
    assert not [n for n in tree.body if isinstance(n, ast.Import | ast.ImportFrom)]
    importing = set()
    for function in (n for n in tree.body if isinstance(n, ast.FunctionDef)):
        for node in ast.walk(function):
            modules = ([a.name for a in node.names] if isinstance(node, ast.Import) else
                       [node.module] if isinstance(node, ast.ImportFrom) else [])
            if any(m.split('.')[0] in ('launch', 'launch_ros') for m in modules):
                importing.add(function.name)
    assert importing == LAUNCH_FUNCTIONS
    # The rules run with `launch` absent.
    launch = _launch_file(monkeypatch)
    nodes = launch['node_parameters']({'seed': '3'})
    assert launch['launch_problem']({'params_file': str(CONFIG_FILE)}, nodes) is None


def test_every_launch_argument_read_is_declared():
    declared = set(_launch_file()['ARGUMENTS'])
    read = set()
    for node in ast.walk(_tree()):
        # configurations.get('x', ...), configurations['x'] and flag('x')
        if isinstance(node, ast.Call) and node.args and isinstance(node.args[0], ast.Constant):
            func = node.func
            if (getattr(func, 'id', None) == 'flag'
                    or (getattr(func, 'attr', None) == 'get'
                        and getattr(func.value, 'id', None) == 'configurations')):
                read.add(node.args[0].value)
        if (isinstance(node, ast.Subscript) and isinstance(node.slice, ast.Constant)
                and getattr(node.value, 'id', None) == 'configurations'):
            read.add(node.slice.value)
    assert read and read <= declared
    assert set(_launch_file()['PARAMETER_ARGUMENTS']) <= declared
    assert {'plant', 'controller', 'scene', 'params', 'seed', 'noise_std_rad', 'record',
            'use_sim_time', 'play', 'bag', 'rviz', 'params_file'} <= declared


def test_the_launch_file_names_only_executables_that_exist():
    nodes = _launch_file()['NODES']
    ours = {executable for executable, package in nodes.items() if package == 'sphere_twin'}
    assert ours == {'simulator', 'reference', 'controller', 'recorder', 'player'}
    assert ours <= _console_scripts()
    assert {(p, e) for e, p in nodes.items() if p != 'sphere_twin'} == {('rviz2', 'rviz2')}


def test_which_nodes_start_for_which_arguments():
    node_parameters = _launch_file()['node_parameters']
    assert list(node_parameters({})) == TWIN
    assert list(node_parameters({'record': 'true'})) == [*TWIN, 'recorder']
    assert list(node_parameters({'play': 'True', 'record': '1'})) == ['player', 'recorder']
    # RViz reads no params file: the launch file puts it on /clock unless told otherwise.
    assert node_parameters({'rviz': 'true'})['rviz2'] == {'use_sim_time': True}
    assert node_parameters({'rviz': 'true', 'use_sim_time': 'false'})['rviz2'] == {
        'use_sim_time': False}


def test_nothing_but_given_arguments_and_sim_time_reaches_the_nodes():
    """An edited params file rules: with no argument given each node gets only the params
    file, and use_sim_time for the nodes on the clock; a given argument reaches exactly the
    nodes that have the parameter, typed."""
    node_parameters = _launch_file()['node_parameters']
    assert node_parameters({'params_file': 'my.yaml'}) == {
        'simulator': {}, 'reference': {'use_sim_time': True},
        'controller': {'use_sim_time': True}}
    given = node_parameters({'real_time_factor': '0.5', 'controller': 'basic', 'seed': '3',
                             'scene': '2', 'use_sim_time': 'false'})
    assert given == {'simulator': {'real_time_factor': 0.5, 'seed': 3, 'scene': '2'},
                     'reference': {'use_sim_time': False},
                     'controller': {'controller': 'basic', 'use_sim_time': False}}
    assert type(given['simulator']['real_time_factor']) is float
    assert node_parameters({'real_time_factor': '1'})['simulator'] == {'real_time_factor': 1.0}
    played = node_parameters({'play': 'true', 'bag': 'run1', 'plant': 'discrete'})
    assert played == {'player': {'bag': 'run1'}}


def _write_yaml(path, sections):
    path.write_text(yaml.safe_dump(sections))
    return path


def _node_args(layers, tmp_path):
    """The --ros-args launch_ros gives a node for its parameter layers: each file as a
    --params-file, each dict written to a file of its own for every node, in order."""
    args = ['--ros-args']
    for k, layer in enumerate(layers):
        if isinstance(layer, dict):
            layer = _write_yaml(tmp_path / f'layer_{k}.yaml', {'/**': {'ros__parameters': layer}})
        args += ['--params-file', str(layer)]
    return args


def _built_use_sim_time(executable, args):
    """use_sim_time of the node, built in this process with ``args`` as its command line."""
    import rclpy

    from sphere_twin.nodes.controller_node import ControllerNode
    from sphere_twin.nodes.reference_node import ReferenceNode
    from sphere_twin.processes import fresh_domain_id

    context = rclpy.Context()
    rclpy.init(context=context, domain_id=fresh_domain_id(), args=args)
    try:
        node = {'reference': ReferenceNode, 'controller': ControllerNode}[executable](
            context=context)
        try:
            return node.get_parameter('use_sim_time').value
        finally:
            node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)


@pytest.mark.parametrize('params, use_sim_time', [
    ('partial', 'true'),  # only a simulator section, as docs/twin.md shows one
    ('wall clock', 'true'),  # a file that sets it false for both
    ('shipped', 'true'),
    ('shipped', 'false'),  # the argument still rules
])
@pytest.mark.parametrize('executable', ['reference', 'controller'])
def test_the_nodes_on_the_clock_keep_sim_time_however_partial_the_params_file(
        params, use_sim_time, executable, tmp_path, monkeypatch):
    """Each node built on the layers the launch file gives it, as rclpy reads them
    (without `launch`): use_sim_time is what the argument says, whatever the file says."""
    monkeypatch.setenv('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    files = {
        'partial': _write_yaml(tmp_path / 'partial.yaml', {'simulator': {'ros__parameters': {
            'real_time_factor': 0.5}}}),
        'wall clock': _write_yaml(tmp_path / 'wall.yaml', {
            name: {'ros__parameters': {'use_sim_time': False}}
            for name in ('reference', 'controller')}),
        'shipped': CONFIG_FILE}
    launch = _launch_file(monkeypatch)  # the rules run without `launch`
    configurations = {'params_file': str(files[params]), 'use_sim_time': use_sim_time}
    layers = launch['node_parameter_layers'](configurations)
    assert layers['simulator'] == [str(files[params])]  # the clock: never on sim time
    assert layers[executable][0] == str(files[params])
    assert _built_use_sim_time(executable, _node_args(layers[executable], tmp_path)) is (
        use_sim_time == 'true')
    if params == 'partial':  # the file alone would have put it on the wall clock
        assert _built_use_sim_time(executable, _node_args(layers[executable][:1], tmp_path)) \
            is False


@pytest.mark.parametrize('name, text, message', [
    ('seed', 'abc', "launch argument seed:='abc' is not an integer"),
    ('real_time_factor', 'fast', "launch argument real_time_factor:='fast' is not a number"),
    ('use_sim_time', 'yes please', "launch argument use_sim_time:='yes please' is not true or "
                                   'false'),
    ('play', 'maybe', "launch argument play:='maybe' is not true or false"),
])
def test_a_malformed_argument_is_one_line_before_anything_starts(name, text, message):
    with pytest.raises(ValueError) as raised:
        _launch_file()['node_parameters']({name: text})
    assert str(raised.value) == message


def _prefix(root, *packages):
    """An install prefix whose ament index lists ``packages``."""
    index = root / 'share' / 'ament_index' / 'resource_index' / 'packages'
    index.mkdir(parents=True)
    for package in packages:
        (index / package).touch()
    return root


def test_rviz_without_rviz2_installed_is_refused_in_one_line(tmp_path, monkeypatch):
    launch_problem = _launch_file()['launch_problem']
    node_parameters = _launch_file()['node_parameters']
    config = {'params_file': str(CONFIG_FILE)}
    monkeypatch.setenv('AMENT_PREFIX_PATH', str(_prefix(tmp_path / 'bare', 'sphere_twin')))
    problem = launch_problem(config, node_parameters({'rviz': 'true'}))
    assert problem.startswith('rviz:=true needs RViz, and rviz2 is not installed')
    assert 'sudo apt install ros-jazzy-rviz2' in problem and '\n' not in problem
    assert launch_problem(config, node_parameters({})) is None  # only asked for with rviz
    monkeypatch.setenv('AMENT_PREFIX_PATH', str(_prefix(tmp_path / 'gui', 'rviz2')))
    assert launch_problem(config, node_parameters({'rviz': 'true'})) is None


def test_a_params_file_that_is_not_there_is_refused(tmp_path):
    launch_problem = _launch_file()['launch_problem']
    missing = tmp_path / 'my.yaml'
    assert launch_problem({'params_file': str(missing)}, {'simulator': {}}) == (
        f'params_file:={missing}: no such file')


# --- through the `launch` packages, where they are installed (a ROS 2 installation) -----

def _import_launch():
    # launch.actions, not launch: from the source tree, launch/ alone would import as an empty
    # namespace package.
    pytest.importorskip('launch.actions')
    pytest.importorskip('launch_ros.actions')


def _launched_nodes(arguments):
    """The Node actions of the launch description for ``arguments`` (name -> text, as
    ``ros2 launch ... name:=text`` sets them), with their substitutions performed."""
    from launch_ros.actions import Node

    from launch import LaunchContext

    context = LaunchContext()
    context.launch_configurations.update(arguments)
    pending = list(_launch_file()['generate_launch_description']().entities)
    nodes = []
    while pending:  # what the launch service does, short of starting the processes
        entity = pending.pop(0)
        if isinstance(entity, Node):
            entity._perform_substitutions(context)
            nodes.append(entity)
        else:
            pending[:0] = entity.visit(context) or []
    return nodes


def _node_gets(node):
    """The params files a node is given, in order: a path, or the dict launch_ros wrote."""
    files = []
    for argument, is_file in node._Node__expanded_parameter_arguments:
        assert is_file  # every parameter goes through a file, none as -p name:=value
        if Path(argument).resolve() == CONFIG_FILE.resolve():
            files.append('twin.yaml')
        else:
            (section,) = yaml.safe_load(Path(argument).read_text()).values()
            files.append(section['ros__parameters'])
    return files


def test_the_launch_description_passes_only_given_arguments(tmp_path, monkeypatch):
    _import_launch()
    monkeypatch.setenv('AMENT_PREFIX_PATH', str(_prefix(tmp_path / 'prefix', 'sphere_twin',
                                                        'rviz2')))
    config = {'params_file': str(CONFIG_FILE)}
    nodes = _launched_nodes(config)
    assert [node.node_executable for node in nodes] == TWIN
    assert {node.node_executable: _node_gets(node) for node in nodes} == {
        'simulator': ['twin.yaml'], 'reference': ['twin.yaml', {'use_sim_time': True}],
        'controller': ['twin.yaml', {'use_sim_time': True}]}
    nodes = _launched_nodes(config | {'real_time_factor': '0.5', 'seed': '4', 'scene': '2',
                                      'controller': 'basic', 'use_sim_time': 'false',
                                      'rviz': 'true'})
    assert {node.node_executable: _node_gets(node) for node in nodes} == {
        'simulator': ['twin.yaml', {'real_time_factor': 0.5, 'seed': 4, 'scene': '2'}],
        'reference': ['twin.yaml', {'use_sim_time': False}],
        'controller': ['twin.yaml', {'controller': 'basic', 'use_sim_time': False}],
        'rviz2': [{'use_sim_time': False}]}


def _stand_in(prefix, executable, script):
    """An executable of the sphere_twin package in ``prefix``: a shell script."""
    path = prefix / 'lib' / 'sphere_twin' / executable
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text('#!/bin/sh\n' + script + '\n')
    path.chmod(0o755)


def _run_launch(arguments):
    """Run the launch file as ``ros2 launch`` does: (exit status, shutdown reasons)."""
    from launch.actions import IncludeLaunchDescription, RegisterEventHandler
    from launch.event_handlers import OnShutdown

    from launch import LaunchDescription, LaunchDescriptionSource, LaunchService

    reasons = []
    service = LaunchService(noninteractive=True)
    service.include_launch_description(LaunchDescription([
        RegisterEventHandler(OnShutdown(on_shutdown=lambda event, _: reasons.append(
            event.reason))),
        IncludeLaunchDescription(
            LaunchDescriptionSource(_launch_file()['generate_launch_description']()),
            launch_arguments=arguments.items())]))
    return service.run(), reasons


@pytest.mark.parametrize('executable, code, status', [
    ('simulator', 3, 1), ('controller', 2, 1),  # a failure: `ros2 launch` says so
    ('reference', 0, 0)])  # a clean exit (as the player's at the end of its bag)
def test_a_required_node_that_exits_ends_the_launch(executable, code, status, tmp_path,
                                                     monkeypatch):
    _import_launch()
    prefix = _prefix(tmp_path / 'prefix', 'sphere_twin')
    for name in TWIN:
        _stand_in(prefix, name, f'sleep 1; exit {code}' if name == executable
                  else 'exec sleep 60')
    monkeypatch.setenv('AMENT_PREFIX_PATH', str(prefix))
    started = time.monotonic()
    returned, reasons = _run_launch({'params_file': str(CONFIG_FILE)})
    assert time.monotonic() - started < 30  # not the 60 s of the other two
    assert returned == status
    # A failure's reason comes through launch's own line for an exception in the launch.
    assert reasons[0].endswith(f'{executable} exited with code {code}; the twin cannot go on '
                               'without it')


@pytest.mark.parametrize('code, failed', [(0, False), (2, True), (1, True), (-2, True),
                                          (-9, True)])
def test_a_required_node_ends_the_launch_with_status_1_if_it_failed(code, failed):
    """Without `launch`: the rule the launch file applies when a node the run needs exits
    (a failure raises in the launch, which `ros2 launch` then ends with status 1)."""
    reason, is_failure = _launch_file()['required_exit']('controller', code)
    assert reason == f'controller exited with code {code}; the twin cannot go on without it'
    assert is_failure is failed


def test_rviz_without_rviz2_ends_the_launch_before_any_node_starts(tmp_path, monkeypatch):
    _import_launch()
    prefix = _prefix(tmp_path / 'prefix', 'sphere_twin')
    for executable in TWIN:
        _stand_in(prefix, executable, f'touch {tmp_path}/{executable}; exec sleep 60')
    monkeypatch.setenv('AMENT_PREFIX_PATH', str(prefix))
    status, _ = _run_launch({'params_file': str(CONFIG_FILE), 'rviz': 'true'})
    assert status == 1
    assert not [name for name in TWIN if (tmp_path / name).exists()]


@pytest.mark.parametrize('executable', ['simulator', 'reference', 'controller', 'recorder',
                                        'player'])
def test_launch_and_config_set_only_parameters_the_node_declares(executable, tmp_path,
                                                                  monkeypatch):
    import rclpy

    from sphere_twin.processes import fresh_domain_id

    monkeypatch.chdir(tmp_path)  # a recorder's default bag would land here
    config = yaml.safe_load(CONFIG_FILE.read_text())[executable]['ros__parameters']
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=fresh_domain_id(),
               args=['--ros-args', '--params-file', str(CONFIG_FILE)])
    try:
        node, declared = _declared(executable, context, tmp_path)
    finally:
        rclpy.try_shutdown(context=context)
    play = 'true' if executable == 'player' else 'false'
    given = _launch_file()['node_parameters'](
        _every_argument_given() | {'play': play, 'record': 'true'})[executable]
    assert set(given) <= declared
    assert set(config) <= declared
    if executable == 'simulator':
        assert node.runner.plant.__class__.__name__ == 'ContinuousPlant'  # the file's choice


def test_setup_installs_launch_rviz_config_and_the_example_bag():
    text = (ROOT / 'setup.py').read_text()
    for folder, pattern in (('launch', 'launch/*.launch.py'), ('rviz', 'rviz/*.rviz'),
                            ('config', 'config/*.yaml'), ('bags/example', 'bags/example/*')):
        assert f"'/{folder}', glob('{pattern}')" in text
    assert list(ROOT.glob('launch/*.launch.py')) and list(ROOT.glob('bags/example/*.mcap'))


def test_rviz_shows_the_markers_and_the_state_in_world():
    rviz = yaml.safe_load(RVIZ_FILE.read_text())['Visualization Manager']
    assert rviz['Global Options']['Fixed Frame'] == 'world'
    topics = {d['Topic']['Value']: d['Class'] for d in rviz['Displays'] if 'Topic' in d}
    assert topics == {'/twin/markers': 'rviz_default_plugins/MarkerArray',
                      '/sphere/state': 'rviz_default_plugins/Odometry'}


def test_package_xml_is_format_3_and_leaves_rviz_optional():
    """launch and launch_ros run the launch file, ros2launch gives `ros2 launch`; RViz is an
    optional GUI (rviz:=true says how to install it), so rosdep does not install it."""
    root = ET.parse(ROOT / 'package.xml').getroot()
    assert root.tag == 'package' and root.get('format') == '3'
    # The order the format 3 schema requires of the leading elements.
    assert [child.tag for child in root][:5] == ['name', 'version', 'description',
                                                 'maintainer', 'license']
    assert root.findtext('name') == 'sphere_twin'
    assert root.find('export').findtext('build_type') == 'ament_python'
    exec_depends = [e.text for e in root.iter('exec_depend')]
    assert len(exec_depends) == len(set(exec_depends))
    assert {'launch', 'launch_ros', 'ros2launch', 'ament_index_python'} <= set(exec_depends)
    assert not {e.text for e in root.iter() if e.tag.endswith('depend')} & {'rviz2'}
