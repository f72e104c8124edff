"""Install sphere_twin as an ament_python ROS 2 package (colcon) or a Python package (pip)."""

from glob import glob

from setuptools import find_packages, setup

PACKAGE_NAME = 'sphere_twin'

setup(
    name=PACKAGE_NAME,
    version='0.1.0',
    packages=find_packages(exclude=['test', 'test.*']),
    package_data={'sphere_sim': ['scenes/*.yaml', 'params/*.yaml', 'tables/*.npz']},
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + PACKAGE_NAME]),
        ('share/' + PACKAGE_NAME, ['package.xml']),
        ('share/' + PACKAGE_NAME + '/scenes', glob('sphere_sim/scenes/*.yaml')),
        ('share/' + PACKAGE_NAME + '/launch', glob('launch/*.launch.py')),
        ('share/' + PACKAGE_NAME + '/rviz', glob('rviz/*.rviz')),
        ('share/' + PACKAGE_NAME + '/config', glob('config/*.yaml')),
        # The example recording, found by name: `sphere-twin report example`, `bag:=example`.
        ('share/' + PACKAGE_NAME + '/bags/example', glob('bags/example/*')),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='sphere_twin maintainers',
    maintainer_email='maintainers@sphere-twin.invalid',
    description='Digital twin of an electrostatically kicked sphere micromirror (ROS 2 Jazzy).',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'sphere-twin = sphere_twin.cli:main',
            # `ros2 run sphere_twin compile_physics`: `sphere-twin compile` in a colcon workspace.
            'compile_physics = sphere_twin.cli:compile_physics',
            # A node's executable takes a Ctrl-C as a clean stop before it imports the node.
            'simulator = sphere_twin.nodes.executables:simulator',
            'monitor = sphere_twin.nodes.executables:monitor',
            'recorder = sphere_twin.nodes.executables:recorder',
            'player = sphere_twin.nodes.executables:player',
            'controller = sphere_twin.nodes.executables:controller',
            'reference = sphere_twin.nodes.executables:reference',
        ],
    },
)
