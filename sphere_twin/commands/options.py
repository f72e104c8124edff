"""Options that several subcommands share, defined once, and the commands' own error."""

from __future__ import annotations

import argparse
import math
import os
from collections.abc import Callable
from pathlib import Path
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
# numpy's and scipy's seeds are unsigned 32-bit integers; a negative one is a traceback there.
seed = _checked_number(int, 'an integer', lambda v: 0 <= v < 2**32,
                       'must be an integer from 0 to 4294967295')


def number_in_range(low: float, high: float, why: str) -> Callable[[str], float]:
    """An argparse type: a finite number in [``low``, ``high``]; a refusal says the range and
    ``why`` it is that (nan and inf fail every comparison, so they are refused too)."""
    kind = 'a positive number' if low > 0.0 else 'a number'
    return _checked_number(float, 'a number', lambda v: low <= v <= high,
                           f'must be {kind} from {low:g} to {high:g} ({why})')


# Relative tolerance of the integrator. Above 1e-2 a kick's outcome goes silently wrong (the
# asymmetric kick turns 0.217 deg at 1e-1 and 6.7 deg at 0.3, against 0.206 deg converged);
# below 1e-12 the error control asks for less than double precision's rounding of the states
# can give, and the run only creeps (1e-12 already takes 15 times as long as 1e-6).
tolerance = number_in_range(1e-12, 1e-2, 'tighter stalls in rounding, looser is inaccurate')
# Simulated durations of a command's runs: up to an hour, which the recordings and sample
# grids hold; longer ones are no study of this device's kicks (tens of milliseconds each).
simulated_seconds = number_in_range(1e-3, 3600.0, 'seconds of simulated time')
# A kick table's grid step in x_sn and y_sn (table build, primitives offsets): finer than
# 0.01 is over 10^4 states of the cone, days of kicks per intensity; the table's own spec
# refuses steps that put nodes outside the unit disc.
GRID_STEP = number_in_range(0.01, 1.0, 'finer is days of kicks')



def _nearest_existing(path: Path) -> Path:
    """``path`` or its nearest ancestor that exists (the current directory at the end)."""
    for candidate in (path, *path.parents):
        if candidate.exists():
            return candidate
    return Path.cwd()


# Where a command writes when not told: the working directory. A command never writes into a
# tracked file or a shipped bag's folder by default; the committed results are regenerated only
# with an explicit `--out bench/results`.
DEFAULT_OUT_DIR = Path('.')


def check_output(text: str, is_file: bool, suffixes: tuple[str, ...] = ()) -> Path:
    """The one check of a path a command will write, made before it computes anything and
    writing nothing: a directory that exists or can be created and is writable; for a file,
    also a file name (not a directory) with one of ``suffixes`` if given."""
    path = Path(text)
    if is_file:
        if text.endswith(('/', os.sep)) or path.is_dir():
            raise argparse.ArgumentTypeError(f'{text} is a directory; give a file name in it')
        if suffixes and path.suffix.lower() not in suffixes:
            raise argparse.ArgumentTypeError(
                f'{text}: the file name must end in {" or ".join(suffixes)}')
    elif path.exists() and not path.is_dir():
        raise argparse.ArgumentTypeError(f'{text} is a file; give a directory')
    directory = path.parent if is_file else path
    existing = _nearest_existing(directory)
    if not existing.is_dir():
        raise argparse.ArgumentTypeError(
            f'cannot create {directory}: {existing} is a file, not a directory')
    if not os.access(existing, os.W_OK | os.X_OK):
        raise argparse.ArgumentTypeError(f'cannot write in {existing}: permission denied')
    return path


def output_directory(text: str) -> Path:
    """argparse type: a directory the command writes into (see :func:`check_output`)."""
    return check_output(text, is_file=False)


def output_file(*suffixes: str) -> Callable[[str], Path]:
    """argparse type: a file the command writes, ending in one of ``suffixes`` if given (see
    :func:`check_output`)."""
    def parse(text: str) -> Path:
        return check_output(text, is_file=True, suffixes=suffixes)
    return parse


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
