"""Options that several subcommands share, defined once."""

import argparse

from msg_defs.device import DEFAULT_PARAMETER_SET
from sphere_sim.model.parameters import ParameterError, available_parameter_sets, load_parameter_set


def parameter_set(text):
    """argparse type: a parameter set's name or YAML file, loaded and checked once, here."""
    try:
        return load_parameter_set(text)
    except ParameterError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from exc


def add_params_option(parser, default=DEFAULT_PARAMETER_SET, help=None):
    """``--params NAME|FILE``: the parameter set the command runs on, as a ParameterSet.

    Every command takes the set this way and passes the loaded set down; a bad name or file
    is a usage error (one line, exit status 2), never a traceback. ``default=None`` leaves the
    choice to something else (a scene's own set).
    """
    shipped = ', '.join(available_parameter_sets())
    parser.add_argument(
        '--params', type=parameter_set, default=default, metavar='NAME|FILE',
        help=help or f'parameter set: a name ({shipped}) or a YAML file with base: and '
                     f'overrides: (default {default})')
