"""The one user CLI, ``sphere-twin``.

Each subcommand lives in its own module under :mod:`sphere_twin.commands` and exposes
``register(subparsers)``; this module only wires them together, so that the CLI calls the
same functions the tests call. A mistake of the user's (a missing or malformed file, a scene
or parameter set that breaks its rules, an option out of range) ends the command with one line,
``sphere-twin <cmd>: error: ...``, and exit status 2; a traceback means a bug (``--debug``
shows it for anything).
"""

import argparse
import importlib
import signal
import sys
import typing
from collections.abc import Sequence

import yaml

from sphere_twin.node_runtime.ros_env import ensure_localhost_discovery

# Modules under sphere_twin.commands, in the order `--help` lists them.
COMMAND_MODULES = (
    'doctor',
    'compile',
    'demo',
    'experiment',
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
    'identify',
    'synthetic',
    'evaluate',
    'bag',
)


USAGE_STATUS = 2  # argparse's status for a usage error; the same for every user mistake
# Ctrl-C ends a command as a shell reports a command SIGINT ended: 128 + the signal's number.
INTERRUPTED_STATUS = 128 + signal.SIGINT


def user_errors() -> tuple[type[Exception], ...]:
    """The exception types that are the user's mistake, not a bug (imported when needed)."""
    from msg_defs.voltage_rules import VoltageRuleError
    from sphere_sim.integrate.segment import SolverError
    from sphere_sim.kicks.design import DesignError
    from sphere_sim.kicks.lookup_table import TableError
    from sphere_sim.kicks.offset_lookup import OffsetError
    from sphere_sim.model.fidelity import FidelityError
    from sphere_sim.model.initial_state import RestError
    from sphere_sim.model.parameters import ParameterError
    from sphere_sim.model.programme import ProgrammeError
    from sphere_sim.model.scene import SceneError
    from sphere_sim.twin.plants import PlantError
    from sphere_twin.bag.reader import BagError
    from sphere_twin.commands.options import CommandError

    return (CommandError, SceneError, ParameterError, ProgrammeError, TableError, BagError,
            DesignError, OffsetError, VoltageRuleError, PlantError, FidelityError, RestError,
            SolverError, yaml.YAMLError, OSError)


def one_line(error: BaseException) -> str:
    """An error's message on one line (YAML's and the OS's span several)."""
    if isinstance(error, OSError) and error.filename is not None:
        return f'{error.filename}: {error.strerror or error}'
    return ' '.join(str(error).split()) or type(error).__name__


class OneLineParser(argparse.ArgumentParser):
    """argparse, but a usage error is the same one line as every other user mistake: the
    usage would be a second line, and ``--help`` shows it to whoever asks."""

    def error(self, message: str) -> typing.NoReturn:
        self.exit(USAGE_STATUS, f'{self.prog}: error: {" ".join(message.split())} '
                                f'(see {self.prog} --help)\n')


def build_parser() -> argparse.ArgumentParser:
    # Subparsers are made of the parser's own class, so every subcommand errs in one line.
    parser = OneLineParser(
        prog='sphere-twin',
        description='Digital twin of an electrostatically kicked sphere micromirror.',
    )
    parser.add_argument('--debug', action='store_true',
                        help='show the traceback of any error, not only of a bug')
    subparsers = parser.add_subparsers(dest='command', metavar='COMMAND', required=True)
    for name in COMMAND_MODULES:
        module = importlib.import_module(f'sphere_twin.commands.{name}')
        module.register(subparsers)
    return parser


def interrupted(error: BaseException) -> bool:
    """Whether ``error`` is Ctrl-C: a KeyboardInterrupt, or what a compiled (numba) function
    makes of one that arrived while it ran (a SystemError "returned a result with an exception
    set", whose cause or context is the KeyboardInterrupt)."""
    seen: set[int] = set()
    current: BaseException | None = error
    while current is not None and id(current) not in seen:
        if isinstance(current, KeyboardInterrupt):
            return True
        seen.add(id(current))
        current = current.__cause__ or current.__context__
    return False


def main(argv: Sequence[str] | None = None) -> int:
    args: argparse.Namespace | None = None
    try:
        ensure_localhost_discovery()
        parser = build_parser()
        args = parser.parse_args(argv)
        return _run(args)
    except (KeyboardInterrupt, SystemError) as error:
        # Ctrl-C is no error of anyone's: one line and 130, whatever was running (the
        # imports, a command, a compiled integration); --debug shows where it was.
        if not interrupted(error) or (args is not None and args.debug):
            raise
        print(f'{_command_name(args)}: interrupted', file=sys.stderr)
        return INTERRUPTED_STATUS


def _run(args: argparse.Namespace) -> int:
    """The command ``args`` names; a user's mistake is one line and USAGE_STATUS."""
    try:
        return args.func(args)
    except user_errors() as error:
        if args.debug:
            raise
        print(f'{_command_name(args)}: error: {one_line(error)}', file=sys.stderr)
        return USAGE_STATUS


def _command_name(args: argparse.Namespace | None) -> str:
    """``sphere-twin <cmd>`` as its lines start (``sphere-twin`` before the command is known)."""
    if args is None:
        return 'sphere-twin'
    return ' '.join(filter(None, ('sphere-twin', args.command, *_subcommands(args))))


def _subcommands(args: argparse.Namespace) -> list[str]:
    """The nested subcommand names (``table build``, ``bag info``), as argparse names them."""
    return [value for key, value in vars(args).items()
            if key.endswith('_command') and isinstance(value, str)]


def compile_physics() -> int:
    """``compile_physics``, the console script a colcon workspace runs
    (``ros2 run sphere_twin compile_physics``): ``sphere-twin compile`` by another name. It
    lives here, not beside the command, so that no command module imports the CLI back."""
    return main(['compile', *sys.argv[1:]])


if __name__ == '__main__':
    sys.exit(main())
