"""Start the twin: simulator, reference and controller, optionally recorder and player.

    ros2 launch sphere_twin twin.launch.py
    ros2 launch sphere_twin twin.launch.py plant:=discrete controller:=basic record:=true
    ros2 launch sphere_twin twin.launch.py rviz:=true

Every stamp of the twin is simulated time (docs/twin.md): the simulator publishes /clock and
never follows it; the other nodes follow it with ``use_sim_time`` (true by default here). With
``play:=true`` the player replays ``bag`` instead of running the simulator and controller.
Parameters not exposed as arguments come from ``config/twin.yaml`` (``params_file``).
Nothing outside ``generate_launch_description`` imports ``launch``, so the file can be read
and checked where the launch packages are not installed.
"""

# Launch arguments: name -> (default, description). An argument passed to a node as the
# parameter of the same name has that parameter's default and description
# (sphere_twin/nodes/parameters.py, or config/twin.yaml's value where it differs on purpose);
# test/test_node_parameters.py checks that they agree.
ARGUMENTS = {
    'plant': ('continuous', 'Plant to run: discrete or continuous (the lookup table of '
                            'kicks).'),
    'controller': ('extended', 'Control law: basic or extended (§4.2).'),
    'scene': ('rest', 'Scene (shipped name or YAML path): parameters, beams, sphere and '
                      'initial state.'),
    'params': ('', 'Parameter set (shipped name or YAML file with base: and overrides:) '
                   'instead of the scene\'s; "" keeps the scene\'s.'),
    'seed': ('0', 'Seed of the measurement noise.'),
    'noise_std_rad': ('0.0', 'Standard deviation of the measured normal per tangential axis '
                             '(rad).'),
    'real_time_factor': ('1.0', 'Simulated seconds per wall second; 0 runs as fast as '
                                'possible.'),
    'use_sim_time': ('true', 'Reference, controller and RViz follow the simulator\'s /clock '
                             '(the simulator and the player publish it).'),
    'record': ('false', 'Also start the recorder (a bag under bags/).'),
    'output_dir': ('', 'Bag directory to create (must not exist or be empty); "" for '
                       'bags/run_<UTC time>.'),
    'play': ('false', 'Replay a bag with the player instead of simulating.'),
    'bag': ('example', 'Bag to play: its directory, one of its .mcap files, a bare .mcap '
                       'file, or the name of a bag installed with the package (example).'),
    'rviz': ('false', 'Also start RViz with rviz/twin.rviz.'),
    'params_file': (None, 'A --params-file for every node (default: the installed '
                          'config/twin.yaml).'),
}


def generate_launch_description():
    from launch.actions import DeclareLaunchArgument
    from launch.conditions import IfCondition, UnlessCondition
    from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
    from launch_ros.actions import Node
    from launch_ros.parameter_descriptions import ParameterValue
    from launch_ros.substitutions import FindPackageShare

    from launch import LaunchDescription

    def arg(name):
        return LaunchConfiguration(name)

    def typed(name, value_type):
        return ParameterValue(arg(name), value_type=value_type)

    share = FindPackageShare('sphere_twin')
    defaults = {'params_file': PathJoinSubstitution([share, 'config', 'twin.yaml'])}
    config = arg('params_file')
    sim_time = {'use_sim_time': typed('use_sim_time', bool)}
    simulating = UnlessCondition(arg('play'))

    actions = [DeclareLaunchArgument(name, default_value=defaults.get(name, default),
                                     description=text)
               for name, (default, text) in ARGUMENTS.items()]
    actions += [
        Node(package='sphere_twin', executable='simulator', name='simulator', output='screen',
             condition=simulating,
             parameters=[config, {'plant': arg('plant'), 'scene': arg('scene'),
                                  'params': arg('params'), 'seed': typed('seed', int),
                                  'noise_std_rad': typed('noise_std_rad', float),
                                  'real_time_factor': typed('real_time_factor', float)}]),
        Node(package='sphere_twin', executable='reference', name='reference', output='screen',
             condition=simulating, parameters=[config, sim_time]),
        Node(package='sphere_twin', executable='controller', name='controller',
             output='screen', condition=simulating,
             parameters=[config, sim_time, {'controller': arg('controller')}]),
        Node(package='sphere_twin', executable='recorder', name='recorder', output='screen',
             condition=IfCondition(arg('record')),
             parameters=[config, {'output_dir': arg('output_dir')}]),
        Node(package='sphere_twin', executable='player', name='player', output='screen',
             condition=IfCondition(arg('play')),
             parameters=[config, {'bag': arg('bag')}]),
        Node(package='rviz2', executable='rviz2', name='rviz2', output='screen',
             condition=IfCondition(arg('rviz')),
             arguments=['-d', PathJoinSubstitution([share, 'rviz', 'twin.rviz'])],
             parameters=[sim_time]),
    ]
    return LaunchDescription(actions)
