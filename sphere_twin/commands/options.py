"""Options that several subcommands share, defined once, and the commands' own error."""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable
from typing import TypeVar

from msg_defs.device import DEFAULT_PARAMETER_SET
from sphere_sim.model.parameters import (
    ParameterError,
    ParameterSet,
    available_parameter_sets,
    load_parameter_set,
)

_T = TypeVar('_T')


class CommandError(Exception):
    """A command cannot do what was asked, for a reason the user can fix (the CLI prints the
    message on one line and exits with status 2)."""


def _checked_number(convert: Callable[[str], _T], kind: str, accept: Callable[[_T], bool],
                    requirement: str) -> Callable[[str], _T]:
    """An argparse type: ``convert`` the text, then ``accept`` the value or say the
    ``requirement``."""
    def parse(text: str) -> _T:
        try:
            value = convert(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f'not {kind}: {text!r}') from None
        if not accept(value):
            raise argparse.ArgumentTypeError(f'{requirement}, got {text}')
        return value
    return parse


positive_float = _checked_number(float, 'a number', lambda v: math.isfinite(v) and v > 0.0,
                                 'must be a positive number')
non_negative_float = _checked_number(float, 'a number',
                                     lambda v: math.isfinite(v) and v >= 0.0,
                                     'must be a number >= 0')
positive_int = _checked_number(int, 'an integer', lambda v: v >= 1, 'must be at least 1')
unit_interval = _checked_number(float, 'a number', lambda v: 0.0 <= v <= 1.0,
                                'must lie in [0, 1]')  # an intensity u_K


def worker_counts(text: str) -> tuple[int, ...]:
    """argparse type: comma-separated worker counts of 2 or more (``2,4,8``); a 1 is dropped,
    since one worker always runs beside them."""
    try:
        counts = sorted({int(part) for part in text.split(',') if part.strip()})
    except ValueError:
        raise argparse.ArgumentTypeError(f'not worker counts like 2,4,8: {text!r}') from None
    counts = [n for n in counts if n != 1]
    if not counts or counts[0] < 2:
        raise argparse.ArgumentTypeError(f'worker counts must be 2 or more, got {text}')
    return tuple(counts)


def parameter_set(text: str) -> ParameterSet:
    """argparse type: a parameter set's name or YAML file, loaded and checked once, here."""
    try:
        return load_parameter_set(text)
    except ParameterError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from exc


def add_params_option(parser: argparse.ArgumentParser, default: str | None = DEFAULT_PARAMETER_SET,
                      help: str | None = None) -> None:
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
