"""The import rules of ARCHITECTURE.md, read from the source (ast; nothing is imported).

* Packages depend one way: ``msg_defs`` ← ``sphere_sim`` ← ``sphere_control`` ← ``sphere_twin``.
  ``sphere_sim`` and ``sphere_control`` are pure libraries: no rclpy, no message types.
* Inside ``sphere_sim`` the rooms do too: ``model`` ← ``integrate`` ← ``studies`` and ``kicks``
  (siblings: neither imports the other) ← ``fitting`` and ``twin`` (siblings too).
* No two modules import each other, directly or round a circle, counting the imports inside
  functions (a circle hidden in a function is still a circle).
* rclpy only in the nodes (``sphere_twin.nodes``), their runtime and the few places that say why.
* Inside ``sphere_twin`` the nodes sit on top: nothing but the nodes imports them, and the
  runtime (``sphere_twin.node_runtime``) imports no other part of the project.
"""

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

# Rank of each top-level package: a module may import its own rank and below.
PACKAGE_RANK = {'msg_defs': 0, 'sphere_sim': 1, 'sphere_control': 2, 'sphere_twin': 3}
# Rooms of one rank are siblings: neither imports the other.
ROOM_RANK = {'model': 0, 'integrate': 1, 'studies': 2, 'kicks': 2, 'fitting': 3, 'twin': 3}
NODES = 'sphere_twin.nodes'
NODE_RUNTIME = 'sphere_twin.node_runtime'
# Modules outside the nodes that may import rclpy, and why.
RCLPY_ALLOWED = {
    'sphere_twin.node_runtime.ros_env': 'the shared main() of every node',
    'sphere_twin.node_runtime.parameter_specs': "declares a node's parameters, inside the "
                                                'functions that do',
    'msg_defs.topics': 'turns its QoS specs into rclpy profiles, inside that one method',
    'sphere_twin.testing': "the tests' probe node that watches a running twin",
    'sphere_twin.bag.reader': "rclpy's CDR deserialiser reads recorded messages; no graph",
    'sphere_twin.synthetic_device': "rclpy's CDR serialiser writes a synthetic device's "
                                    'recording; no graph',
}


def module_name(path):
    parts = list(path.relative_to(ROOT).with_suffix('').parts)
    if parts[-1] == '__init__':
        parts.pop()
    return '.'.join(parts)


def project_modules():
    modules = {}
    for package in PACKAGE_RANK:
        for path in sorted((ROOT / package).rglob('*.py')):
            modules[module_name(path)] = path
    return modules


MODULES = project_modules()


def imports_of(name, path):
    """Every module that ``name`` imports, at top level or inside functions."""
    found = set()
    is_package = path.name == '__init__.py'
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = name.split('.')
                base = base[:len(base) - node.level + (1 if is_package else 0)]
                target = '.'.join(base + ([node.module] if node.module else []))
            else:
                target = node.module
            # ``from package import module`` imports the module; anything else, the target.
            submodules = {f'{target}.{alias.name}' for alias in node.names} & set(MODULES)
            found.update(submodules or {target})
    return found


CLI = 'sphere_twin.cli'


def cli_command_modules():
    """The command modules the CLI loads by name (``importlib``, which ``imports_of`` cannot
    see), read from its ``COMMAND_MODULES`` table."""
    tree = ast.parse(MODULES[CLI].read_text())
    table = next(node.value for node in tree.body if isinstance(node, ast.Assign)
                 and any(getattr(t, 'id', None) == 'COMMAND_MODULES' for t in node.targets))
    return {f'sphere_twin.commands.{ast.literal_eval(element)}' for element in table.elts}


IMPORTS = {name: imports_of(name, path) for name, path in MODULES.items()}
# The CLI's loads by name count as imports: a command module that imported the CLI back would
# be a circle all the same.
IMPORTS[CLI] |= cli_command_modules()


def project_target(target):
    """The project module an import names (the longest known prefix), or None."""
    parts = target.split('.')
    for n in range(len(parts), 0, -1):
        candidate = '.'.join(parts[:n])
        if candidate in MODULES:
            return candidate
    return None


def rank(name):
    parts = name.split('.')
    package = PACKAGE_RANK[parts[0]]
    room = ROOM_RANK.get(parts[1], -1) if parts[0] == 'sphere_sim' and len(parts) > 1 else -1
    return package, room


def upward_imports():
    bad = []
    for name, targets in IMPORTS.items():
        mine_package, mine_room = rank(name)
        for target in filter(None, map(project_target, targets)):
            package, room = rank(target)
            if package > mine_package:
                bad.append(f'{name} -> {target} (package above)')
            # Inside sphere_sim, its own __init__ is room -1: importable from every room.
            elif package == mine_package == PACKAGE_RANK['sphere_sim'] and room > mine_room:
                bad.append(f'{name} -> {target} (room above)')
            elif (package == mine_package == PACKAGE_RANK['sphere_sim'] and room == mine_room
                  and room >= 0 and name.split('.')[1] != target.split('.')[1]):
                bad.append(f'{name} -> {target} (sibling room)')
    return bad


def circles():
    graph = {name: {t for t in map(project_target, targets) if t and t != name}
             for name, targets in IMPORTS.items()}
    # A package's __init__ is imported on the way to its modules; only edges between modules
    # that hold code count, and the __init__ files here hold only docstrings.
    found, state = [], {}

    def visit(node, stack):
        state[node] = 'open'
        stack.append(node)
        for nxt in sorted(graph[node]):
            if state.get(nxt) == 'open':
                found.append(' -> '.join([*stack[stack.index(nxt):], nxt]))
            elif nxt not in state:
                visit(nxt, stack)
        stack.pop()
        state[node] = 'done'

    for name in sorted(graph):
        if name not in state:
            visit(name, [])
    return found


def in_package(name, package):
    return name == package or name.startswith(package + '.')


def test_the_source_tree_is_what_the_rules_read():
    # The rules below hold only if they see the code: every package and room is found.
    assert {'sphere_sim.model.dynamics', 'sphere_sim.integrate.radau_compiled',
            'sphere_sim.studies.pullin', 'sphere_sim.kicks.lookup_table',
            'sphere_twin.nodes.simulator_node', 'sphere_twin.nodes.controller_node',
            'sphere_twin.cli', 'msg_defs.topics',
            'sphere_twin.node_runtime.ros_env'} <= set(MODULES)
    rooms = {name.split('.')[1] for name in MODULES if name.startswith('sphere_sim.')}
    assert rooms == set(ROOM_RANK), 'a module of sphere_sim sits outside the rooms'
    # Every node an executable starts lives in the nodes' room.
    nodes = {name for name in MODULES if name.endswith('_node')}
    assert len(nodes) == 6 and all(in_package(name, NODES) for name in nodes)


def test_no_package_or_room_imports_upward():
    assert upward_imports() == []


def test_no_modules_import_each_other_in_a_circle():
    assert circles() == []


def test_the_clis_loads_by_name_are_read_as_imports():
    commands = cli_command_modules()
    assert {'sphere_twin.commands.compile', 'sphere_twin.commands.demo'} <= commands
    assert commands <= set(MODULES)  # every name in the table is a module that exists
    assert commands <= IMPORTS[CLI]


def test_the_architecture_page_draws_the_order_the_rules_keep():
    """docs/architecture.md's one-way chains name the packages and sphere_sim's rooms in the
    ranks this test enforces."""
    page = (ROOT / 'docs' / 'architecture.md').read_text()
    packages = ' ← '.join(f'`{p}`' for p in sorted(PACKAGE_RANK, key=PACKAGE_RANK.get))
    ranks = sorted(set(ROOM_RANK.values()))
    rooms = ' ← '.join(' and '.join(r for r in ROOM_RANK if ROOM_RANK[r] == rank)
                       for rank in ranks)
    assert packages in page
    assert rooms in ' '.join(page.split())


def test_rclpy_only_in_the_nodes():
    bad = [name for name, targets in IMPORTS.items()
           if any(t == 'rclpy' or t.startswith('rclpy.') for t in targets)
           and not in_package(name, NODES) and name not in RCLPY_ALLOWED]
    assert bad == []


def test_the_libraries_use_no_ros():
    """sphere_sim and sphere_control: no rclpy, no message types, no node runtime."""
    ros_packages = ('rclpy', 'std_msgs', 'geometry_msgs', 'sensor_msgs', 'nav_msgs',
                    'trajectory_msgs', 'visualization_msgs', 'diagnostic_msgs', 'rosgraph_msgs',
                    'rcl_interfaces', 'builtin_interfaces', 'action_msgs',
                    'unique_identifier_msgs')
    libraries = [name for name in MODULES
                 if in_package(name, 'sphere_sim') or in_package(name, 'sphere_control')]
    bad = [f'{name} -> {target}' for name in libraries for target in sorted(IMPORTS[name])
           if target.split('.')[0] in ros_packages or in_package(target, NODE_RUNTIME)
           or target in ('msg_defs.topics', 'msg_defs.conversions', 'msg_defs.markers')]
    assert bad == []


def test_nothing_imports_actionlib_msgs():
    """Deprecated in Jazzy and gone after it: its old bags are read by field names
    (msg_defs.conversions), the contract uses action_msgs."""
    assert [name for name, targets in IMPORTS.items()
            if any(t.split('.')[0] == 'actionlib_msgs' for t in targets)] == []


def test_only_nodes_import_nodes_and_the_runtime_imports_no_project_module():
    bad = [f'{name} -> {target}' for name, targets in IMPORTS.items()
           for target in filter(None, map(project_target, targets))
           if (in_package(target, NODES) and not in_package(name, NODES)
               and target != NODES)
           or (in_package(name, NODE_RUNTIME) and not in_package(target, NODE_RUNTIME)
               and target != 'sphere_twin')]
    assert bad == []


@pytest.mark.parametrize('source, expected', [
    ('from sphere_twin.cli import main\n',
     ['sphere_sim.model.fake -> sphere_twin.cli (package above)']),
    ('from sphere_sim.kicks import design\n',
     ['sphere_sim.model.fake -> sphere_sim.kicks.design (room above)']),
    ('def f():\n    from sphere_sim.twin.runner import TwinRunner\n',
     ['sphere_sim.model.fake -> sphere_sim.twin.runner (room above)']),
    ('from sphere_sim.model.parameters import ParameterSet\nimport msg_defs.device\n', []),
])
def test_the_rules_catch_an_upward_import(tmp_path, monkeypatch, source, expected):
    fake = tmp_path / 'fake.py'
    fake.write_text(source)
    monkeypatch.setitem(IMPORTS, 'sphere_sim.model.fake', imports_of('sphere_sim.model.fake', fake))
    assert [b for b in upward_imports() if 'fake' in b] == expected


def test_the_rules_catch_a_circle(monkeypatch):
    monkeypatch.setitem(IMPORTS, 'sphere_sim.model.parameters',
                        IMPORTS['sphere_sim.model.parameters'] | {'sphere_sim.model.scene'})
    assert any('sphere_sim.model.parameters' in c and 'sphere_sim.model.scene' in c
               for c in circles())


def test_an_install_puts_only_the_four_packages_into_site_packages():
    """setup.py installs what find_packages finds: no generic top-level name beside ours."""
    from setuptools import find_packages

    packages = find_packages(str(ROOT), exclude=['test', 'test.*'])
    assert {name.split('.')[0] for name in packages} == set(PACKAGE_RANK)
    assert {'sphere_twin.nodes', 'sphere_twin.node_runtime'} <= set(packages)
