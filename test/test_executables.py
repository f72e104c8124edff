"""setup.py's node executables: each installs the shutdown handlers before it imports its node
(sphere_twin.nodes.executables), so a Ctrl-C in a node's first second is a clean stop."""

import ast
import importlib
import subprocess
import sys
from pathlib import Path

import pytest

from sphere_twin.nodes import executables

ROOT = Path(__file__).resolve().parents[1]
NODES = {'simulator', 'controller', 'reference', 'recorder', 'player', 'monitor'}


def _entry_points():
    tree = ast.parse((ROOT / 'setup.py').read_text())
    scripts = next(node for node in ast.walk(tree) if isinstance(node, ast.Dict)
                   and any(getattr(k, 'value', None) == 'console_scripts' for k in node.keys))
    listed = scripts.values[0].elts
    return dict(tuple(part.strip() for part in item.value.split('=')) for item in listed)


def test_every_node_executable_goes_through_the_executables_module():
    entries = _entry_points()
    nodes = {name for name, target in entries.items() if target.startswith('sphere_twin.nodes')}
    assert nodes == NODES
    assert all(entries[name] == f'sphere_twin.nodes.executables:{name}' for name in NODES)


def test_each_executable_runs_the_main_of_its_own_node(monkeypatch):
    started = []
    monkeypatch.setattr(executables, 'run_node_module', lambda module: started.append(module))
    for name in sorted(NODES):
        getattr(executables, name)()
    assert started == [f'sphere_twin.nodes.{name}_node' for name in sorted(NODES)]
    for module in started:
        assert callable(importlib.import_module(module).main)


def test_the_executables_module_imports_neither_rclpy_nor_numpy():
    """What runs before the handlers are installed must be quick: the node's heavy imports
    come after them."""
    code = ('import sys, sphere_twin.nodes.executables; '
            'print(sorted({"rclpy", "numpy", "numba"} & set(sys.modules)))')
    done = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                          cwd=ROOT, timeout=60, check=True)
    assert done.stdout.strip() == '[]'


# The child signals itself once the node's module reaches the import of `module`: a Ctrl-C
# that lands inside the node's imports, deterministically.
INTERRUPTED_IMPORT = '''
import os, signal, sys

class InterruptAt:
    def find_spec(self, name, path=None, target=None):
        if name == {module!r}:
            os.kill(os.getpid(), signal.SIGINT)
        return None

sys.meta_path.insert(0, InterruptAt())
from sphere_twin.nodes.executables import {executable}
sys.exit({executable}())
'''


@pytest.mark.parametrize('executable, module', [('controller', 'rclpy'),
                                                ('simulator', 'numpy'),
                                                ('reference', 'rclpy')])
def test_a_sigint_inside_the_nodes_imports_is_a_clean_stop(executable, module):
    """`ros2 launch` stopped in its first second: the nodes were still importing rclpy, numpy
    and numba, and each printed a KeyboardInterrupt traceback and died with -2."""
    code = INTERRUPTED_IMPORT.format(module=module, executable=executable)
    done = subprocess.run([sys.executable, '-c', code, '--ros-args'], capture_output=True,
                          text=True, cwd=ROOT, timeout=120)
    assert (done.returncode, done.stdout, done.stderr) == (0, '', '')
