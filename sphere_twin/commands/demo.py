"""``sphere-twin demo``: the closed loop as separate processes, recorded to a bag.

Starts the recorder, the simulator (the continuous model of §3 by default, or the discrete
kick table; paced), the reference node and the extended controller on a fresh ROS domain;
runs the default scenario (the Fig. 13 setpoint, then the trajectory of eq. (64)); stops every
node by its PID; and reports what happened, read back from the bag it recorded as
`sphere-twin report` reads it: kicks, final and RMS error, the real-time factor each node saw,
late programmes, the bag and a plot of the error against run time. The trajectory's RMS error
is set beside the offline closed loop's on the same controller, plant, reference and kick
period (:func:`sphere_twin.scenario.offline_loop`): the ROS loop should track as well.
"""

from __future__ import annotations

import argparse
import datetime
import math
import os
import re
import sys
import time
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import TextIO

import numpy as np
from numpy.typing import ArrayLike

from sphere_sim.twin.plant_setup import PLANT_KINDS
from sphere_twin.commands.options import positive_float
from sphere_twin.node_runtime.ros_env import DISCOVERY_RANGE_VAR
from sphere_twin.processes import (
    NodeProcess,
    NodeSpec,
    fresh_domain_id,
    parameter_args,
    running_nodes,
)
from sphere_twin.scenario import (
    SETPOINT_XY,
    TRAJECTORY_OFFSET_S,
    RunLog,
    offline_loop,
    scenario_nodes,
)

DEFAULT_SETPOINT_S = 8.0  # simulated seconds on the setpoint before the trajectory starts
DEFAULT_TRAJECTORY_S = 25.0  # half a period of eq. (64): out to A_max and back to the centre
# The continuous plant runs at a quarter of the device's pace: the paper's friction costs about
# 1.7 times the compute of a dry kick, and half real time no longer keeps every programme on time
# here. The kick table costs nothing to integrate, but publishing every sample takes a quarter
# of the wall time at the device's pace on a quiet machine and over half on a loaded one
# (measured: at 2x, 46 of 63 programmes late; at 1x, 0-1 late alone but 54 of 61 within the
# test suite), so it runs at half the device's pace until the node publishes off its
# integrating thread.
DEFAULT_REAL_TIME_FACTOR = {'continuous': 0.25, 'discrete': 0.5}
DEFAULT_PLANT = 'continuous'
START_TIMEOUT_S = 60.0
WALL_MARGIN = 3.0  # the run may take this many times its paced duration before it is cut
# Subscribers of /sphere/surface_normal the simulator waits for: recorder, controller, and the
# demo's own probe.
DEMO_NORMAL_SUBSCRIBERS = 3
# Subscribers of /clock it waits for: the recorder (it records /clock) and the reference (on
# simulated time). Counting the recorder alone once let a run start, and end, before the
# reference heard the clock: it held its setpoint throughout.
DEMO_CLOCK_SUBSCRIBERS = 2
# Each node's farewell line ends with the real-time factor it saw; the simulator's also counts
# the programmes that arrived after their start.
REAL_TIME_FACTOR_PATTERN = re.compile(r'real-time factor (\S+?);?(?:\s|$)')
LATE_PATTERN = re.compile(r'\((\d+) late\)')


def demo_nodes(bag_dir: str | os.PathLike[str], setpoint_s: float, real_time_factor: float,
               seed: int, plant: str = DEFAULT_PLANT) -> tuple[NodeSpec, ...]:
    """What the demo starts, in start order (stopped in reverse: the recorder last)."""
    return (NodeSpec('recorder', tuple(parameter_args(output_dir=str(bag_dir)))),
            *scenario_nodes(setpoint_s, plant, real_time_factor, seed,
                            DEMO_NORMAL_SUBSCRIBERS, DEMO_CLOCK_SUBSCRIBERS))


def run_demo(setpoint_s: float = DEFAULT_SETPOINT_S, trajectory_s: float = DEFAULT_TRAJECTORY_S,
             real_time_factor: float | None = None, bags_dir: str | os.PathLike[str] = 'bags',
             seed: int = 0, out: TextIO | None = None, plant: str = DEFAULT_PLANT) -> int:
    """Run the scenario; returns 0 if the loop ran and every node exited cleanly, else 1.

    ``real_time_factor`` defaults to the plant's (:data:`DEFAULT_REAL_TIME_FACTOR`).
    """
    from msg_defs.topics import CONTROLLER_STATUS, SURFACE_NORMAL
    from sphere_twin.testing import TopicProbe, TwinTimeoutError

    out = sys.stdout if out is None else out
    if real_time_factor is None:
        real_time_factor = DEFAULT_REAL_TIME_FACTOR[plant]

    def say(line: str) -> None:
        print(line, file=out, flush=True)

    domain_id = fresh_domain_id()
    stamp = datetime.datetime.now(datetime.UTC).strftime('%Y%m%dT%H%M%SZ')
    bag_dir = Path(bags_dir) / f'demo_{stamp}'
    duration_s = setpoint_s + trajectory_s
    say(f'demo: ROS_DOMAIN_ID={domain_id}, '
        f'{DISCOVERY_RANGE_VAR}={os.environ.get(DISCOVERY_RANGE_VAR, "LOCALHOST (default)")}')
    say(f'demo: scenario: setpoint {SETPOINT_XY} for {setpoint_s:g} s, then eq. (64) '
        f'(A_max 0.44, f1 0.02 Hz, from t = {TRAJECTORY_OFFSET_S:g} s, where it passes the '
        f'centre) for {trajectory_s:g} s of simulated time, {plant} plant, paced at '
        f'{real_time_factor:g}x real time')
    problems: list[str] = []
    *others, simulator = demo_nodes(bag_dir, setpoint_s, real_time_factor, seed, plant)
    with running_nodes(*others, domain_id=domain_id) as group:
        for process in group.processes:
            say(f'demo: started {process.name} (pid {process.pid})')
        probe = TopicProbe(domain_id, (SURFACE_NORMAL, CONTROLLER_STATUS))
        log = RunLog(probe)
        try:
            probe.spin_until(log.controller_ready, START_TIMEOUT_S,
                             'controller holding the reference')
            process = group.start(simulator.executable, simulator.args)
            say(f'demo: started {process.name} (pid {process.pid})')
        except TwinTimeoutError as error:
            problems.append(str(error).splitlines()[0])
        started = time.monotonic()
        try:
            probe.spin_until(lambda: log.kicks() > 0, START_TIMEOUT_S, 'first kick')
            say(f'demo: the loop runs: first kick at {log.simulated_s():.2f} s simulated')
            wall_limit = WALL_MARGIN * duration_s / real_time_factor + START_TIMEOUT_S
            probe.spin_until(lambda: log.simulated_s() >= duration_s, wall_limit,
                             f'{duration_s:g} s of simulated time')
        except TwinTimeoutError as error:
            problems.append(str(error).splitlines()[0])
        except KeyboardInterrupt:
            problems.append('interrupted')
        wall_s = time.monotonic() - started
        probe.close()
        say(f'demo: stopping {" then ".join(p.name for p in reversed(group.processes))} '
            f'(SIGINT to each PID)')
        group.stop_all()
    problems += _report_exits(group.processes, say)
    _report_pace(group.processes, say)
    say('demo: the offline loop on the same controller, plant, reference and kick period '
        '(no ROS) ...')
    offline = offline_loop(setpoint_s, duration_s, plant)
    problems += _report_bag(bag_dir, setpoint_s, log, wall_s, say,
                            _trajectory_rms_rad(offline.times_s, offline.errors_rad, setpoint_s))
    say(f'demo: bag {bag_dir}')
    if problems:
        say('demo: FAILED: ' + '; '.join(problems))
        return 1
    say('demo: OK: recorder, simulator, reference and controller ran as separate processes '
        f'on domain {domain_id} and exited with 0')
    return 0


def _report_exits(processes: Iterable[NodeProcess], say: Callable[[str], None]) -> list[str]:
    """Each node's last lines and exit code; the problems (non-zero exits)."""
    problems: list[str] = []
    for process in processes:
        for line in (process.stderr_text() + process.stdout_text()).splitlines()[-3:]:
            say(f'  {process.name:>10} | {line}')
        say(f'demo: stopped {process.name} (pid {process.pid}), exit code {process.returncode}')
        if process.returncode != 0:
            problems.append(f'{process.name} exited with {process.returncode}')
    return problems


def _report_pace(processes: Iterable[NodeProcess], say: Callable[[str], None]) -> None:
    """Say the real-time factor each node saw and the late programmes (those that started
    later than the controller asked: the simulator fell behind), from their farewell lines."""
    factors, late = [], None
    for process in processes:
        text = process.stdout_text()
        found = REAL_TIME_FACTOR_PATTERN.findall(text)
        if found:
            factors.append(f'{process.name} {float(found[-1]):.2f}')
        if process.name == 'simulator' and LATE_PATTERN.search(text):
            late = int(LATE_PATTERN.findall(text)[-1])
    say(f'demo: real-time factor: {", ".join(factors)}; late programmes: '
        f'{"unknown" if late is None else late}')


def _trajectory_rms_rad(times_s: ArrayLike, errors_rad: ArrayLike, setpoint_s: float) -> float:
    """RMS of the errors from the trajectory's start on (rad); NaN before it."""
    tracking = np.asarray(times_s) >= setpoint_s
    return (math.sqrt(float(np.mean(np.asarray(errors_rad)[tracking] ** 2))) if tracking.any()
            else math.nan)


def _report_bag(bag_dir: Path, setpoint_s: float, log: RunLog, wall_s: float,
                say: Callable[[str], None], offline_rms_rad: float) -> list[str]:
    """What the run did, read back from its own bag as `sphere-twin report` reads it, beside
    the offline loop's trajectory RMS error, and a plot; the problems (an unreadable bag, no
    normal recorded)."""
    from sphere_twin.bag.reader import BagError
    from sphere_twin.run_analysis import errors_at_decisions_rad, errors_rad, load_run, plot_report

    try:
        recorded = load_run(bag_dir)
        times, errors = errors_rad(recorded)
    except BagError as error:
        return [str(error)]
    if times.size == 0:
        return ['no surface normal crossed between the processes']
    plot = plot_report(recorded, bag_dir.parent / f'{bag_dir.name}_error.png',
                       title=f'{bag_dir.name}: setpoint, then eq. (64) from {setpoint_s:g} s')
    on_setpoint = (times > 0.5 * setpoint_s) & (times < setpoint_s)
    simulated_s = log.simulated_s()
    say(f'demo: {log.kicks()} kicks in {simulated_s:.1f} s simulated '
        f'({log.kicks() / max(simulated_s, 1e-9):.1f} per second), {wall_s:.1f} s wall from the '
        'simulator\'s start')
    if on_setpoint.any():
        say(f'demo: setpoint: final error {math.degrees(errors[on_setpoint][-1]):.4f} deg')
    # Like for like: the error where the loop decided (settled states), as the offline loop
    # records it; and over every sample, kicks in flight included.
    decided_t_s, decided_errors_rad = errors_at_decisions_rad(recorded)
    rms_rad = _trajectory_rms_rad(decided_t_s, decided_errors_rad, setpoint_s)
    if math.isfinite(rms_rad):
        say(f'demo: trajectory RMS error {math.degrees(rms_rad):.3f} deg (offline loop: '
            f'{math.degrees(offline_rms_rad):.3f} deg)')
        say(f'demo: trajectory: RMS error over every sample, kicks in flight included, '
            f'{math.degrees(_trajectory_rms_rad(times, errors, setpoint_s)):.3f} deg; final '
            f'error {math.degrees(errors[-1]):.3f} deg')
    say(f'demo: plot {plot}')
    return []


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add the ``demo`` subcommand to the ``sphere-twin`` parser."""
    parser = subparsers.add_parser(
        'demo', help='the closed loop as separate processes, recorded to a bag',
        description='Start recorder, simulator, reference and controller as processes on a '
                    'fresh ROS domain (discovery limited to localhost), run the Fig. 13 '
                    'setpoint and then the eq. (64) trajectory, stop every node by PID, '
                    'and report kicks, errors, real-time factor, the bag and a plot.')
    parser.add_argument('--setpoint-s', type=positive_float, default=DEFAULT_SETPOINT_S,
                        help='simulated seconds on the setpoint')
    parser.add_argument('--trajectory-s', type=positive_float, default=DEFAULT_TRAJECTORY_S,
                        help='simulated seconds on the trajectory')
    parser.add_argument('--plant', choices=PLANT_KINDS, default=DEFAULT_PLANT,
                        help='the simulator\'s plant: the continuous model of §3, or the '
                             'discrete table of kicks (the paper\'s shortcut)')
    parser.add_argument('--real-time-factor', type=positive_float, default=None,
                        help='simulated seconds per wall second (default: '
                             + ', '.join(f'{v:g} for the {k} plant'
                                         for k, v in DEFAULT_REAL_TIME_FACTOR.items()) + ')')
    parser.add_argument('--bags-dir', default='bags', help='where the bag directory goes')
    parser.add_argument('--seed', type=int, default=0)
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Entry point of the subcommand; returns the exit code."""
    return run_demo(args.setpoint_s, args.trajectory_s, args.real_time_factor, args.bags_dir,
                    args.seed, plant=args.plant)
