"""Start the twin: simulator, reference and controller, optionally recorder and player.

    ros2 launch sphere_twin twin.launch.py
    ros2 launch sphere_twin twin.launch.py plant:=discrete controller:=basic record:=true
    ros2 launch sphere_twin twin.launch.py fidelity:=sliding
    ros2 launch sphere_twin twin.launch.py params_file:=my.yaml
    ros2 launch sphere_twin twin.launch.py rviz:=true

Every node reads its parameters from ``params_file`` (default: the installed
``config/twin.yaml``). An argument that sets a node parameter (plant, scene, ...) is passed to
the node only when it is given, so an edited params file is not overridden by defaults of the
launch file. Every stamp of the twin is simulated time (docs/twin.md): the simulator publishes
/clock and never follows it; reference and controller follow it with ``use_sim_time``, which
the launch file passes them after the params file, true unless ``use_sim_time:=false``, so a
params file without their sections (or one that sets it false) cannot put them on the wall
clock. With ``play:=true`` the player replays ``bag``
instead of running the simulator and controller. If a node the run needs exits, the launch
ends, with status 1 if the node failed (:func:`required_exit`). Nothing at module level
imports anything, and :func:`node_parameters` and
:func:`launch_problem` import no ``launch``, so the file can be read and its rules checked
where the launch packages are not installed (test/test_launch.py).
"""

# An argument's default that means "not given": the node keeps the params file's value.
NOT_GIVEN = ''
_FROM_FILE = ' Default "": the params file\'s value.'

# Launch arguments: name -> (default, description). An argument passed to a node as the
# parameter of the same name (PARAMETER_ARGUMENTS) defaults to NOT_GIVEN and has that
# parameter's description (sphere_twin/nodes/parameters.py) followed by _FROM_FILE;
# test/test_node_parameters.py checks that they agree.
ARGUMENTS = {
    'plant': (NOT_GIVEN, 'Plant to run: continuous (the physics of §3) or discrete (the '
                         'lookup table of kicks: it starts faster; its sphere and beams rest '
                         'between kicks); "" for the one fidelity names (continuous where both '
                         'are "").' + _FROM_FILE),
    'fidelity': (NOT_GIVEN, 'Rung of the ladder of models the plant serves kicks from: full (the '
                            'paper\'s model), sliding (leaves out stiction and presliding: '
                            'cheaper, outside the live error budget) or table (the discrete '
                            'plant); "" for the plant\'s own (full on the continuous plant, the '
                            'live default).' + _FROM_FILE),
    'controller': (NOT_GIVEN, 'Control law: basic or extended (§4.2).' + _FROM_FILE),
    'scene': (NOT_GIVEN, 'Scene (shipped name or YAML path): parameters, beams, sphere and '
                         'initial state.' + _FROM_FILE),
    'params': (NOT_GIVEN, 'Parameter set (shipped name or YAML file with base: and overrides:) '
                          'instead of the scene\'s; "" keeps the scene\'s.' + _FROM_FILE),
    'seed': (NOT_GIVEN, 'Seed of the measurement noise.' + _FROM_FILE),
    'noise_std_rad': (NOT_GIVEN, 'Standard deviation of the measured normal per tangential '
                                 'axis (rad).' + _FROM_FILE),
    'real_time_factor': (NOT_GIVEN, 'Simulated seconds per wall second; 0 runs as fast as '
                                    'possible.' + _FROM_FILE),
    'use_sim_time': ('true', 'Reference, controller and RViz follow the simulator\'s /clock (the '
                             'simulator and the player publish it): true whatever the params '
                             'file says; false puts them on the wall clock.'),
    'record': ('false', 'Also start the recorder (a bag under bags/).'),
    'output_dir': (NOT_GIVEN, 'Bag directory to create (must not exist or be empty); "" for '
                              'bags/run_<UTC time>.' + _FROM_FILE),
    'play': ('false', 'Replay a bag with the player instead of simulating.'),
    'bag': (NOT_GIVEN, 'Bag to play: its directory, one of its .mcap files, a bare .mcap '
                       'file, or the name of a bag installed with the package '
                       '(example).' + _FROM_FILE),
    'rviz': ('false', 'Also start RViz with rviz/twin.rviz (rviz2 is not a dependency of the '
                      'package: sudo apt install ros-jazzy-rviz2).'),
    'params_file': (None, 'A --params-file for every node (default: the installed '
                          'config/twin.yaml).'),
}

# Arguments passed as the node parameter of the same name, only when given (use_sim_time
# always: its default is true, not NOT_GIVEN): name -> (type of the parameter, the nodes that
# take it).
PARAMETER_ARGUMENTS = {
    'plant': ('str', ('simulator',)),
    'fidelity': ('str', ('simulator',)),
    'scene': ('str', ('simulator',)),
    'params': ('str', ('simulator',)),
    'seed': ('int', ('simulator',)),
    'noise_std_rad': ('float', ('simulator',)),
    'real_time_factor': ('float', ('simulator',)),
    # Never the simulator's (it is the clock and refuses use_sim_time:=true) nor the player's
    # (it publishes /clock); the nodes that follow the clock get it after the params file.
    'use_sim_time': ('bool', ('reference', 'controller', 'rviz2')),
    'controller': ('str', ('controller',)),
    'output_dir': ('str', ('recorder',)),
    'bag': ('str', ('player',)),
}

# Executable -> package of every node the launch file can start. The twin's own nodes are
# all required: when one exits (a crash, a bad parameter, the player at the end of its bag),
# what is left cannot go on, so the launch ends rather than run on half a twin. RViz is not.
NODES = {'simulator': 'sphere_twin', 'reference': 'sphere_twin', 'controller': 'sphere_twin',
         'recorder': 'sphere_twin', 'player': 'sphere_twin', 'rviz2': 'rviz2'}

# A node parameter's value as the launch file passes it.
Value = bool | int | float | str

# The text a boolean launch argument may take, as launch's IfCondition reads it.
_BOOLEANS = {'true': True, '1': True, 'false': False, '0': False}
_TYPE_NAMES = {'bool': 'true or false', 'int': 'an integer', 'float': 'a number'}


def _value(name: str, text: str, kind: str) -> Value:
    """``text`` of argument ``name`` as a value of type ``kind``, or a one-line ValueError.
    Parsed as launch_ros's ParameterValue(value_type=...) would, but before any node starts."""
    try:
        if kind == 'bool':
            return _BOOLEANS[text.strip().lower()]
        if kind == 'int':
            return int(text)
        if kind == 'float':
            return float(text)
    except (KeyError, ValueError):
        raise ValueError(f'launch argument {name}:={text!r} is not {_TYPE_NAMES[kind]}') from None
    return text


def node_parameters(configurations: dict[str, str]) -> dict[str, dict[str, Value]]:
    """The nodes to start for these launch configurations (argument name -> text, as
    ``ros2 launch ... name:=text`` gives them; an absent one takes its default), each with the
    parameters the launch file passes it on top of the params file: the arguments given, so
    the params file's value stands for the others, and use_sim_time (true by default) to the
    nodes that follow /clock, whatever the params file says. A malformed argument is a
    ValueError."""
    def flag(name: str) -> bool:
        return bool(_value(name, configurations.get(name, ARGUMENTS[name][0]), 'bool'))

    started = ['player'] if flag('play') else ['simulator', 'reference', 'controller']
    if flag('record'):
        started.append('recorder')
    if flag('rviz'):
        started.append('rviz2')
    nodes: dict[str, dict[str, Value]] = {name: {} for name in started}
    for name, (kind, takers) in PARAMETER_ARGUMENTS.items():
        text = configurations.get(name, ARGUMENTS[name][0])
        if text == NOT_GIVEN:
            continue
        value = _value(name, text, kind)  # checked even for a node not started: a typo
        for node in takers:
            if node in nodes:
                nodes[node][name] = value
    return nodes


def node_parameter_layers(configurations: dict[str, str]) -> dict[str, list[str | dict]]:
    """What each node of :func:`node_parameters` is given, in the order launch_ros passes it
    (a later layer wins a parameter both set): the params file (``configurations
    ['params_file']``; RViz reads none), then the parameters the launch file sets."""
    params_file = configurations.get('params_file')
    return {executable: ([params_file] if params_file is not None and executable != 'rviz2'
                         else []) + ([given] if given else [])
            for executable, given in node_parameters(configurations).items()}


def required_exit(executable: str, returncode: int | None) -> tuple[str, bool]:
    """What the exit of a node the run needs does to the launch: the reason it ends, and
    whether that is a failure (a code other than 0, or a signal's negative one), which ends
    it with status 1. A clean exit (the player at the end of its bag) ends it with 0."""
    failed = returncode != 0
    return (f'{executable} exited with code {returncode}; the twin cannot go on without it',
            failed)


def launch_problem(configurations: dict[str, str], nodes: dict[str, dict]) -> str | None:
    """Why these nodes cannot start, in one line, or None: checked before any starts."""
    import os

    from ament_index_python.packages import PackageNotFoundError, get_package_prefix

    params_file = configurations.get('params_file')
    # launch_ros only warns about a --params-file that is not a file and starts the node
    # without it: every parameter would silently be the node's default.
    if params_file is not None and not os.path.isfile(params_file):
        return f'params_file:={params_file}: no such file'
    if 'rviz2' in nodes:
        try:
            get_package_prefix('rviz2')
        except PackageNotFoundError:
            return ('rviz:=true needs RViz, and rviz2 is not installed (not in the ament index '
                    'of AMENT_PREFIX_PATH): sudo apt install ros-jazzy-rviz2, or leave '
                    'rviz:=false')
    return None


def generate_launch_description():
    from launch.actions import DeclareLaunchArgument, OpaqueFunction
    from launch.substitutions import PathJoinSubstitution
    from launch_ros.substitutions import FindPackageShare

    from launch import LaunchDescription

    defaults = {'params_file': PathJoinSubstitution([FindPackageShare('sphere_twin'), 'config',
                                                     'twin.yaml'])}
    actions = [DeclareLaunchArgument(name, default_value=defaults.get(name, default),
                                     description=text)
               for name, (default, text) in ARGUMENTS.items()]
    # The nodes are chosen and given their parameters once the arguments are known: an
    # argument not given then passes nothing, which a substitution cannot express.
    actions.append(OpaqueFunction(function=_node_actions))
    return LaunchDescription(actions)


def _node_actions(context):
    """The Node actions for the launch configurations of ``context``; raises (one line, the
    launch ends with status 1) before any node starts if an argument or file is wrong."""
    from launch.actions import Shutdown
    from launch.substitutions import PathJoinSubstitution
    from launch_ros.actions import Node
    from launch_ros.parameter_descriptions import ParameterValue
    from launch_ros.substitutions import FindPackageShare

    configurations = dict(context.launch_configurations)
    nodes = node_parameters(configurations)
    problem = launch_problem(configurations, nodes)
    if problem is not None:
        raise RuntimeError(problem)

    def ends_the_launch(executable):
        def on_exit(event, exit_context):
            if exit_context.is_shutdown:  # stopped by the launch (Ctrl-C): nothing to add
                return None
            reason, failed = required_exit(executable, event.returncode)
            if failed:
                # Jazzy's LaunchService returns 0 after a Shutdown, whatever its reason: only an
                # exception raised in the launch makes it return 1 (`ros2 launch`'s status). It
                # then shuts the launched system down as Shutdown does, saying so in one line:
                # `Caught exception in launch (see debug for traceback): <reason>`.
                raise RuntimeError(reason)
            return Shutdown(reason=reason)
        return on_exit

    def for_launch_ros(layer):
        # launch_ros reads a plain string as YAML (scene:=2 would reach the node as an
        # integer); ParameterValue keeps it the string parameter it is.
        if not isinstance(layer, dict):
            return layer  # the params file
        return {name: ParameterValue(value, value_type=str) if isinstance(value, str)
                else value for name, value in layer.items()}

    actions = []
    for executable, layers in node_parameter_layers(configurations).items():
        parameters = [for_launch_ros(layer) for layer in layers]
        if executable == 'rviz2':
            actions.append(Node(
                package=NODES[executable], executable=executable, name=executable,
                output='screen', parameters=parameters,
                arguments=['-d', PathJoinSubstitution([FindPackageShare('sphere_twin'), 'rviz',
                                                       'twin.rviz'])]))
            continue
        actions.append(Node(
            package=NODES[executable], executable=executable, name=executable, output='screen',
            parameters=parameters, on_exit=ends_the_launch(executable)))
    return actions
