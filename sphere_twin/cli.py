"""The one user CLI, ``sphere-twin``.

Each subcommand lives in its own module under :mod:`sphere_twin.commands` and exposes
``register(subparsers)``; this module only wires them together, so that the CLI calls the
same functions the tests call.
"""

import argparse
import importlib
import sys

from node_runtime.ros_env import ensure_localhost_discovery

# Modules under sphere_twin.commands, in the order `--help` lists them.
COMMAND_MODULES = (
    'doctor',
    'demo',
    'kick',
    'pullin',
    'calibrate',
    'capacitance',
    'validate',
    'optimize',
    'table',
    'bench',
    'primitives',
    'report',
    'replay_check',
    'evaluate',
    'bag',
)


def build_parser():
    parser = argparse.ArgumentParser(
        prog='sphere-twin',
        description='Digital twin of an electrostatically kicked sphere micromirror.',
    )
    subparsers = parser.add_subparsers(dest='command', metavar='COMMAND', required=True)
    for name in COMMAND_MODULES:
        module = importlib.import_module(f'sphere_twin.commands.{name}')
        module.register(subparsers)
    return parser


def main(argv=None):
    ensure_localhost_discovery()
    parser = build_parser()
    args = parser.parse_args(argv)
    return args.func(args)


if __name__ == '__main__':
    sys.exit(main())
