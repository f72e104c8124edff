"""``sphere-twin bench startup``: how long the simulator takes from launch to its first message.

Installs the source tree into a scratch prefix as colcon does (:mod:`sphere_twin.scratch_install`,
numba's cache beside the installed kernels, so the first start is cold), then launches the
``simulator`` executable from there once cold (it compiles the physics and says so) and
``--warm-runs`` times warm (it loads the physics from numba's cache), and times each from the
launch to the first ``/sphere/surface_normal`` a subscriber receives; then times the parts of a
warm start in one more process (imports, the cache check, building the plant). Writes
``startup.{json,md}`` into ``--out``; its last line is
``startup to the first message: cold <c> s, warm <w> s (median of <n>; target 5 s)``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import platform
import re
import statistics
import sys
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any, TextIO

from sphere_twin.commands.doctor import MAX_DOMAIN_ID
from sphere_twin.commands.options import (
    DEFAULT_OUT_DIR,
    CommandError,
    output_directory,
    positive_int,
)

DEFAULT_WARM_RUNS = 3
# The target for every start after the first (a node publishes within this).
TARGET_WARM_S = 5.0
# A cold start on a loaded 2-core machine took over a minute; this only stops a stuck one.
START_TIMEOUT_S = 600.0
STOP_TIMEOUT_S = 10.0
PLANT = 'continuous'  # the one whose samples run the compiled physics from the first tick on
# The parts of a warm start, timed in a child that runs from the install as the node does.
_PHASES_PROBE = f'''
import json, time
started = time.perf_counter()
import rclpy, sphere_twin.nodes.simulator_node
imported = time.perf_counter()
from sphere_sim.twin.precompile import physics_compiled
warm = physics_compiled()
checked = time.perf_counter()
from sphere_sim.twin.plant_setup import build_plant
build_plant({PLANT!r}, 'rest')
built = time.perf_counter()
print(json.dumps({{'imports_s': imported - started, 'cache_check_s': checked - imported,
                  'build_plant_s': built - checked, 'warm': warm}}))
'''
PHASES_TIMEOUT_S = 300.0


@dataclasses.dataclass(frozen=True)
class StartupRun:
    """One start: cold or warm, its wall time to the first message, and what it compiled.

    Attributes
    ----------
    kind : str
        'cold' or 'warm'.
    first_message_s : float
        From launching the process to the first /sphere/surface_normal received (s).
    announced_compile : bool
        The node said it was compiling the physics.
    compile_s : float or None
        How long it said the compiling took (s).
    """

    kind: str
    first_message_s: float
    announced_compile: bool
    compile_s: float | None


def ros_domain_id(text: str) -> int:
    """argparse type: a ROS domain id, 0 to MAX_DOMAIN_ID (rmw's range)."""
    if not text.strip().isdigit() or int(text) > MAX_DOMAIN_ID:
        raise argparse.ArgumentTypeError(
            f'must be a ROS domain id from 0 to {MAX_DOMAIN_ID}, got {text}')
    return int(text)


def register(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add ``startup`` to the ``bench`` subcommands."""
    parser = sub.add_parser(
        'startup', help='simulator start-up to its first message, cold and warm',
        description='Install the source tree into a scratch prefix as colcon does, then time '
                    'the simulator (continuous plant) from launch to its first '
                    '/sphere/surface_normal: once cold (it compiles the physics) and '
                    '--warm-runs times from numba\'s cache. Writes startup.{json,md} into '
                    '--out. Needs the source tree.')
    parser.add_argument('--warm-runs', type=positive_int, default=DEFAULT_WARM_RUNS,
                        help='warm starts, of which the median is reported (default '
                             '%(default)s)')
    parser.add_argument('--domain-id', type=ros_domain_id, default=None,
                        help='ROS_DOMAIN_ID of the runs (default: a fresh one)')
    parser.add_argument('--out', type=output_directory, default=DEFAULT_OUT_DIR,
                        help='output directory')
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from sphere_twin.scratch_install import InstallError

    try:
        run_startup_bench(args.warm_runs, args.out, args.domain_id)
    except InstallError as error:
        raise CommandError(str(error)) from None
    return 0


def run_startup_bench(warm_runs: int = DEFAULT_WARM_RUNS,
                      out_dir: str | os.PathLike[str] = DEFAULT_OUT_DIR,
                      domain_id: int | None = None,
                      stream: TextIO = sys.stdout) -> dict[str, Any]:
    """Install, start cold once and warm ``warm_runs`` times; write and return the summary."""
    from sphere_twin.processes import fresh_domain_id
    from sphere_twin.scratch_install import install_into

    domain_id = fresh_domain_id() if domain_id is None else domain_id
    load_before = os.getloadavg()
    runs: list[StartupRun] = []
    with tempfile.TemporaryDirectory(prefix='sphere_twin_startup_') as scratch:
        install = install_into(Path(scratch) / 'install')
        print(f'installed into {install.prefix}; ROS domain {domain_id}', file=stream,
              flush=True)
        for kind in ['cold'] + ['warm'] * warm_runs:
            runs.append(time_first_message(install.executable('simulator'),
                                           install.environment(), domain_id, kind))
            print(_run_line(runs[-1]), file=stream, flush=True)
        phases = warm_start_phases(install.environment())
    print('of a warm start: ' + _phases_text(phases), file=stream, flush=True)
    summary = _summary(runs, phases, load_before)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / 'startup.json').write_text(json.dumps(summary, indent=2) + '\n')
    (out_dir / 'startup.md').write_text(markdown(summary))
    print(summary_line(summary), file=stream, flush=True)
    return summary


def time_first_message(executable: Path, env: dict[str, str], domain_id: int,
                       kind: str, timeout_s: float = START_TIMEOUT_S) -> StartupRun:
    """Launch ``executable`` (the simulator) and time it to the first surface normal that a
    subscriber, in this process and listening before the launch, receives."""
    from msg_defs.topics import SURFACE_NORMAL
    from sphere_sim.twin.precompile import COMPILED_LINE, COMPILING_LINE
    from sphere_twin.processes import parameter_args, start_node, stop
    from sphere_twin.testing import TopicProbe

    probe = TopicProbe(domain_id, [SURFACE_NORMAL])
    try:
        started = time.perf_counter()
        process = start_node(str(executable), parameter_args(plant=PLANT), env, domain_id)
        try:
            probe.process = process
            probe.spin_until(lambda: probe.messages[SURFACE_NORMAL.name], timeout_s,
                             f'{SURFACE_NORMAL.name} from the simulator')
            first_message_s = time.perf_counter() - started
        finally:
            stop(process, STOP_TIMEOUT_S)
    finally:
        probe.close()
    log = process.stderr_text() + process.stdout_text()
    compiled = re.search(re.escape(COMPILED_LINE) + r' ([0-9.]+) s', log)
    return StartupRun(kind, first_message_s, COMPILING_LINE in log,
                      float(compiled.group(1)) if compiled else None)


def warm_start_phases(env: dict[str, str]) -> dict[str, float]:
    """Seconds of a warm start's parts, timed in a child Python run with ``env`` (the
    install's): importing the node, checking numba's cache, building the plant."""
    import subprocess

    with tempfile.TemporaryDirectory() as cwd:  # not the source tree: '' leads sys.path
        result = subprocess.run([sys.executable, '-c', _PHASES_PROBE], env={**os.environ, **env},
                                cwd=cwd, capture_output=True, text=True,
                                timeout=PHASES_TIMEOUT_S, check=True)
    phases: dict[str, float] = json.loads(result.stdout.strip().splitlines()[-1])
    return phases


def _phases_text(phases: dict[str, float]) -> str:
    return (f"importing the node {phases['imports_s']:.2f} s, importing the kernels and "
            f"checking numba's cache {phases['cache_check_s']:.2f} s, building the plant "
            f"(loading the kernels, relaxing the rest pose) {phases['build_plant_s']:.2f} s")


def _run_line(run: StartupRun) -> str:
    said = (f'; it compiled the physics in {run.compile_s:.1f} s' if run.compile_s is not None
            else '; it compiled nothing' if not run.announced_compile else '')
    return f'{run.kind} start: first message after {run.first_message_s:.2f} s{said}'


def _summary(runs: Sequence[StartupRun], phases: dict[str, float],
             load_before: Sequence[float]) -> dict[str, Any]:
    import numba

    cold = [r for r in runs if r.kind == 'cold']
    warm = [r.first_message_s for r in runs if r.kind == 'warm']
    return {
        'plant': PLANT,
        'cold_s': cold[0].first_message_s if cold else None,
        'cold_compile_s': cold[0].compile_s if cold else None,
        'warm_s': warm,
        'warm_median_s': statistics.median(warm) if warm else None,
        'target_warm_s': TARGET_WARM_S,
        'runs': [dataclasses.asdict(r) for r in runs],
        'warm_start_phases_s': phases,
        'cpu_count': os.cpu_count(),
        'load_average_before': list(load_before),
        'load_average_after': list(os.getloadavg()),
        'python': platform.python_version(),
        'numba': numba.__version__,
    }


def summary_line(summary: dict[str, Any]) -> str:
    return (f"startup to the first message: cold {summary['cold_s']:.1f} s, warm "
            f"{summary['warm_median_s']:.2f} s (median of {len(summary['warm_s'])}; target "
            f"{summary['target_warm_s']:g} s)")


def markdown(summary: dict[str, Any]) -> str:
    rows = [f"| {r['kind']} | {r['first_message_s']:.2f} | "
            + (f"{r['compile_s']:.1f}" if r['compile_s'] is not None else '-')
            + f" | {'yes' if r['announced_compile'] else 'no'} |" for r in summary['runs']]
    met = 'met' if summary['warm_median_s'] <= summary['target_warm_s'] else 'missed'
    return '\n'.join([
        '# Start-up of the simulator from an install location', '',
        'Written by `sphere-twin bench startup`. Wall time from launching the `simulator` '
        'executable of a fresh colcon-style install (`setup.py install` into a scratch '
        "prefix; numba's cache beside the installed kernels) to the first "
        '`/sphere/surface_normal` a subscriber receives (it listens before the launch, so '
        f"DDS discovery is included); plant {summary['plant']}, scene rest. The cold start "
        "compiles the physics and says so; the warm ones load it from numba's cache.", '',
        '| start | to the first message (s) | compiling, as the node said (s) | '
        'said "compiling" |', '|---|---|---|---|', *rows, '',
        f"{summary_line(summary)}: {met}.", '',
        'Of a warm start, timed in one more process run from the install: '
        + _phases_text(summary['warm_start_phases_s'])
        + '; the rest of it is the interpreter, rclpy and DDS discovery.', '',
        f"{summary['cpu_count']} cores; load average (1, 5, 15 min) "
        + ', '.join(f'{x:.2f}' for x in summary['load_average_before']) + ' before, '
        + ', '.join(f'{x:.2f}' for x in summary['load_average_after'])
        + f" after; Python {summary['python']}, numba {summary['numba']}.", ''])
