"""``sphere-twin compile``: compile the physics ahead of time, once per install location.

numba compiles the kernels on their first call and caches the machine code beside the installed
sources (or in its user-wide cache directory where those are read-only). Without this, the
first start of the simulator compiles them itself (it says so). ``make setup`` runs this; in a
colcon workspace the same command is ``ros2 run sphere_twin compile_physics``. A second run
finds everything cached and returns at once; ``--check`` only says whether it would compile.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import TextIO

from sphere_twin.commands.options import CommandError

# Exit status of --check when the physics is not compiled (2 is a usage error).
NOT_COMPILED_STATUS = 1


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    parser = subparsers.add_parser(
        'compile', help='compile the physics ahead of time (once per install location)',
        description='Compile every numba kernel of the physics into numba\'s cache for this '
                    'install location, so that the nodes start without compiling; does '
                    'nothing when it is already compiled. In a colcon workspace: ros2 run '
                    'sphere_twin compile_physics.')
    parser.add_argument('--check', action='store_true',
                        help='only say whether the physics is compiled: exit 0 if so, '
                             f'{NOT_COMPILED_STATUS} if not')
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    return check(sys.stdout) if args.check else compile_here(sys.stdout)


def _places(directories: Sequence[Path]) -> str:
    return ', '.join(map(str, directories))


def check(out: TextIO) -> int:
    """Say whether every kernel is cached here; 0 if so, NOT_COMPILED_STATUS if not."""
    from sphere_sim.twin.kernel_cache import cache_directories, cached_kernels, missing_kernels

    kernels = cached_kernels()
    missing = missing_kernels(kernels)
    places = _places(cache_directories(kernels))
    if not missing:
        print(f'compiled: all {len(kernels)} kernels of the physics are cached in {places}',
              file=out)
        return 0
    print(f'not compiled: {len(missing)} of {len(kernels)} kernels of the physics have no '
          f'machine code in {places} (first: {missing[0]}); run sphere-twin compile', file=out)
    return NOT_COMPILED_STATUS


def compile_here(out: TextIO) -> int:
    """Compile what is not cached yet and say where it went and how long it took."""
    from sphere_sim.twin.kernel_cache import cache_directories, cached_kernels, missing_kernels
    from sphere_sim.twin.precompile import (
        COLD_COMPILE_ESTIMATE_S,
        compile_physics,
        install_location,
    )

    started = time.perf_counter()
    kernels = cached_kernels()
    if not missing_kernels(kernels):
        print(f'already compiled: all {len(kernels)} kernels of the physics are cached in '
              f'{_places(cache_directories(kernels))} (checked in '
              f'{time.perf_counter() - started:.2f} s)', file=out)
        return 0
    print(f'compiling the physics for {install_location()} (once per install location; about '
          f'{COLD_COMPILE_ESTIMATE_S:.0f} s on a 2-core machine) ...', file=out, flush=True)
    report = compile_physics()
    if report.missing:
        raise CommandError(f'compiled, but numba cached no machine code for '
                           f'{len(report.missing)} kernels ({", ".join(report.missing)}) in '
                           f'{_places(report.cache_dirs)}')
    print(f'compiled {report.kernels} kernels in {report.elapsed_s:.1f} s; cached in '
          f'{_places(report.cache_dirs)}', file=out)
    return 0
