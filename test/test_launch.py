"""launch/twin.launch.py, rviz/twin.rviz and config/twin.yaml, checked without the `launch`
package (not on PyPI): what the launch file names exists, and every node starts on the
params file."""

import ast
import re
from pathlib import Path

import pytest
import yaml

ROOT = Path(__file__).resolve().parents[1]
LAUNCH_FILE = ROOT / 'launch' / 'twin.launch.py'
CONFIG_FILE = ROOT / 'config' / 'twin.yaml'
RVIZ_FILE = ROOT / 'rviz' / 'twin.rviz'


def _tree():
    return ast.parse(LAUNCH_FILE.read_text())


def _console_scripts():
    text = (ROOT / 'setup.py').read_text()
    return set(re.findall(r"'([\w-]+) = [\w.]+:main'", text))


def _node_calls():
    """(executable, parameter names given as literals) of every Node(...) in the file."""
    tree = _tree()
    assigned = {node.targets[0].id: node.value for node in ast.walk(tree)
                if isinstance(node, ast.Assign) and isinstance(node.targets[0], ast.Name)}
    calls = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Call) and getattr(node.func, 'id', None) == 'Node':
            kw = {k.arg: k.value for k in node.keywords}
            names = set()
            for item in getattr(kw.get('parameters'), 'elts', []):
                item = assigned.get(item.id, item) if isinstance(item, ast.Name) else item
                if isinstance(item, ast.Dict):
                    names |= {k.value for k in item.keys}
            calls.append((kw['package'].value, kw['executable'].value, names))
    return calls


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


def test_the_launch_file_imports_launch_only_inside_generate_launch_description():
    tree = _tree()
    assert not [n for n in tree.body if isinstance(n, ast.Import | ast.ImportFrom)]
    functions = [n.name for n in tree.body if isinstance(n, ast.FunctionDef)]
    assert functions == ['generate_launch_description']


def test_every_launch_argument_used_is_declared():
    namespace = {}
    exec(compile(_tree(), str(LAUNCH_FILE), 'exec'), namespace)  # defines, imports nothing
    declared = set(namespace['ARGUMENTS'])
    used = {node.args[0].value for node in ast.walk(_tree())
            if isinstance(node, ast.Call) and getattr(node.func, 'id', None) in ('arg', 'typed')
            and isinstance(node.args[0], ast.Constant)}
    assert used <= declared and used
    assert {'plant', 'controller', 'scene', 'params', 'seed', 'noise_std_rad', 'record',
            'use_sim_time', 'play', 'bag', 'rviz'} <= declared


def test_the_launch_file_names_only_executables_that_exist():
    calls = _node_calls()
    ours = {executable for package, executable, _ in calls if package == 'sphere_twin'}
    assert ours == {'simulator', 'reference', 'controller', 'recorder', 'player'}
    assert ours <= _console_scripts()
    assert {(p, e) for p, e, _ in calls if p != 'sphere_twin'} == {('rviz2', 'rviz2')}


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
    (given,) = [names for _, e, names in _node_calls() if e == executable]
    assert given <= declared
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
