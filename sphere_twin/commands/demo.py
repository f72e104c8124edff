"""``sphere-twin demo``: the closed loop as separate processes, recorded to a bag.

Says first what to expect: the plant, the rung of the ladder of models it runs (the full model
at the live tolerance, or the kick table), the pace and the wall time the run should take.
Starts the recorder, the simulator (the continuous model of §3 by default, or the discrete
kick table; paced), the reference node and the extended controller on the ROS domain of
``ROS_DOMAIN_ID`` (a fresh one if it is unset); runs the default scenario (the Fig. 13
setpoint, then the trajectory of eq. (64)), saying its progress every few seconds; stops every
node by its PID; and reports what happened, every figure read back from the bag it recorded as
`sphere-twin report` reads it: kicks, final and RMS error, the real-time factor each node saw,
late programmes, the bag and a plot of the error against run time. The trajectory's RMS error
is set beside the offline closed loop's on the same controller, plant, reference and kick
period (:func:`sphere_twin.scenario.offline_loop`): the ROS loop should track as well.

SIGINT (Ctrl-C) and SIGTERM end it the same way: it stops its nodes, summarises the run so far
and exits with 130 or 143 (128 + the signal's number, as a shell reports it).
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime
import math
import os
import re
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, TextIO

import numpy as np
from numpy.typing import ArrayLike

from sphere_sim.integrate.tolerances import CHECK_RTOL, LIVE_METHOD, LIVE_RTOL
from sphere_sim.twin.plant_setup import (
    FIDELITIES,
    LIVE_FIDELITY,
    PLANT_KINDS,
    plant_and_fidelity,
)
from sphere_twin.commands.options import (
    CommandError,
    check_output,
    positive_float,
    simulated_seconds,
)
from sphere_twin.node_runtime.ros_env import DISCOVERY_RANGE_VAR, DOMAIN_ID_VAR
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

if TYPE_CHECKING:
    from sphere_twin.testing import TopicProbe

DEFAULT_SETPOINT_S = 8.0  # simulated seconds on the setpoint before the trajectory starts
DEFAULT_TRAJECTORY_S = 25.0  # half a period of eq. (64): out to A_max and back to the centre
# Both plants run at half the device's pace. The continuous plant's kicks cost about 55 ms of
# compute each by the live twin's W-method (LIVE_METHOD), half of Radau's: at 0.5 the simulator
# held 0.48 with 15 of 506 programmes late, on a machine busy with two other jobs (by Radau at
# 0.25 it had held 0.19, 56 late). The kick table costs nothing to integrate, but publishing
# every sample takes a quarter of the wall time at the device's pace on a quiet machine and over
# half on a loaded one (measured: at 2x, 46 of 63 programmes late; at 1x, 0-1 late alone but 54
# of 61 within the test suite), so it runs at half the device's pace until the node publishes
# off its integrating thread.
DEFAULT_REAL_TIME_FACTOR = {'continuous': 0.5, 'discrete': 0.5}
DEFAULT_PLANT = 'continuous'
LIVE_INTEGRATION = f'rtol {LIVE_RTOL:g}, {LIVE_METHOD}'  # how the continuous plant integrates
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
# The simulator's farewell with check_fidelity: the divergence from the full model.
FIDELITY_CHECK_PATTERN = re.compile(r'fidelity check: ([^\n]*)')
# What ends the demo as Ctrl-C does: it stops its nodes, summarises, and exits with 128 + the
# signal's number (130, 143), as a shell reports a command a signal ended.
DEMO_STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)
SIGNAL_EXIT_BASE = 128
# ROS 2 domain ids are 0..232 (the DDS port formula); the fresh ones come from 1..101.
MAX_ROS_DOMAIN_ID = 232
# A bag that ends this many simulated seconds before the run the demo watched lost its end.
BAG_LAG_S = 0.5


def model_fidelity(fidelity: str) -> str:
    """What the rung ``fidelity`` of the ladder of models (:mod:`sphere_sim.model.fidelity`)
    is, in words."""
    from sphere_sim.model.fidelity import FULL, TABLE_RUNG, rung_named

    if fidelity == TABLE_RUNG:
        return ("each kick's landing looked up in the kick tables, nothing integrated (the "
                "ladder's last rung)")
    if fidelity == FULL.name:
        return f'the full model of the paper at the live tolerance ({LIVE_INTEGRATION})'
    return (f'the paper\'s model at the live tolerance ({LIVE_INTEGRATION}), leaving out '
            f'{rung_named(fidelity).leaves_out}')


def wall_time_text(seconds: float) -> str:
    """A duration as a person reads it: seconds below 90 s, minutes below 90 min, hours."""
    if seconds < 90.0:
        return f'{seconds:.0f} s'
    if seconds < 5400.0:
        return f'{seconds / 60.0:.1f} min'
    return f'{seconds / 3600.0:.1f} h'


def demo_start_lines(plant: str, real_time_factor: float, setpoint_s: float,
                     trajectory_s: float, fidelity: str) -> list[str]:
    """What the demo says before it starts a node: the plant and its model's rung, the pace
    and the wall time it should take (the simulated duration over the pace), the scenario."""
    duration_s = setpoint_s + trajectory_s
    return [
        f'demo: {plant} plant, model {fidelity}: {model_fidelity(fidelity)}',
        f'demo: {duration_s:g} s of simulated time at {real_time_factor:g} of real time: about '
        f'{wall_time_text(duration_s / real_time_factor)} of wall time, plus the offline loop',
        f'demo: scenario: setpoint {SETPOINT_XY} for {setpoint_s:g} s, then eq. (64) (A_max '
        f'0.44, f1 0.02 Hz, from t = {TRAJECTORY_OFFSET_S:g} s, where it passes the centre) '
        f'for {trajectory_s:g} s of simulated time',
    ]


def demo_nodes(bag_dir: str | os.PathLike[str], setpoint_s: float, real_time_factor: float,
               seed: int, plant: str = DEFAULT_PLANT, check_fidelity: bool = False,
               fidelity: str = '') -> tuple[NodeSpec, ...]:
    """What the demo starts, in start order (stopped in reverse: the recorder last)."""
    return (NodeSpec('recorder', tuple(parameter_args(output_dir=str(bag_dir)))),
            *scenario_nodes(setpoint_s, plant, real_time_factor, seed,
                            DEMO_NORMAL_SUBSCRIBERS, DEMO_CLOCK_SUBSCRIBERS,
                            check_fidelity=check_fidelity, fidelity=fidelity))


@dataclasses.dataclass(frozen=True)
class LiveRun:
    """What the node loop left: its processes (stopped), its problems, how far it got."""

    processes: list[NodeProcess]
    problems: list[str]
    simulated_s: float  # the last surface normal the demo's own probe heard


class StopSignals:
    """SIGINT and SIGTERM while the demo runs: noted, never raised, so that the demo stops its
    nodes by PID and summarises the run either way (a raised KeyboardInterrupt could land in
    the middle of starting or stopping a node; SIGTERM's default would orphan them). The first
    signal counts; later ones are ignored while it stops."""

    def __init__(self) -> None:
        self.signum: int | None = None
        self._previous: dict[int, Any] = {}

    def __enter__(self) -> StopSignals:
        self.install()
        return self

    def __exit__(self, *exc: object) -> None:
        for signum, handler in self._previous.items():
            # None: a handler not set from Python (rclpy's); put back Python's default.
            signal.signal(signum, handler if handler is not None else
                          signal.default_int_handler if signum == signal.SIGINT
                          else signal.SIG_DFL)

    def install(self) -> None:
        """(Re)install the handlers: rclpy installs its own when a context starts."""
        if threading.current_thread() is not threading.main_thread():
            return  # Python delivers signals to the main thread only
        for signum in DEMO_STOP_SIGNALS:
            previous = signal.signal(signum, self._note)
            self._previous.setdefault(signum, previous)

    def _note(self, signum: int, frame: object) -> None:
        if self.signum is None:
            self.signum = signum

    @property
    def requested(self) -> bool:
        return self.signum is not None

    @property
    def name(self) -> str:
        return signal.Signals(self.signum).name if self.signum is not None else ''

    @property
    def exit_status(self) -> int:
        """128 + the signal's number, as a shell reports a command the signal ended."""
        return SIGNAL_EXIT_BASE + (self.signum or 0)


class _StoppedError(Exception):
    """Raised from the offline loop's progress callback when a stop signal came."""


def check_bags_dir(bags_dir: str | os.PathLike[str]) -> Path:
    """The bags directory, created if missing; CommandError unless it is (or can be made) a
    writable directory. Checked before any node starts: the recorder would otherwise fail
    on it only after the start-up timeout."""
    try:
        path = check_output(str(bags_dir), is_file=False)
    except argparse.ArgumentTypeError as error:
        raise CommandError(f'--bags-dir: {error}') from None
    path.mkdir(parents=True, exist_ok=True)
    return path


def demo_domain_id(environ: Mapping[str, str]) -> tuple[int, str]:
    """The ROS domain of the run and where it came from: ``ROS_DOMAIN_ID`` if the environment
    sets it (the user chose that graph), else a fresh one no other run on this machine holds.

    Raises
    ------
    CommandError
        If ``ROS_DOMAIN_ID`` is set but is not a domain id.
    """
    given = environ.get(DOMAIN_ID_VAR, '').strip()
    if not given:
        return fresh_domain_id(), f'fresh: {DOMAIN_ID_VAR} is unset'
    if not given.isdigit() or int(given) > MAX_ROS_DOMAIN_ID:
        raise CommandError(f'{DOMAIN_ID_VAR}={given!r} is not a ROS domain id (an integer '
                           f'from 0 to {MAX_ROS_DOMAIN_ID}); unset it for a fresh one')
    return int(given), 'from the environment'


def run_demo(setpoint_s: float = DEFAULT_SETPOINT_S, trajectory_s: float = DEFAULT_TRAJECTORY_S,
             real_time_factor: float | None = None, bags_dir: str | os.PathLike[str] = 'bags',
             seed: int = 0, out: TextIO | None = None, plant: str = '',
             check_fidelity: bool = False, fidelity: str = '') -> int:
    """Run the scenario; returns 0 if the loop ran and every node exited cleanly, 1 if not,
    and 128 + the signal's number (130, 143) if SIGINT or SIGTERM stopped it.

    ``plant`` and ``fidelity`` are the simulator's (either decides, '' leaves it to the other:
    :func:`~sphere_sim.twin.plant_setup.plant_and_fidelity`). ``real_time_factor`` defaults
    to the plant's (:data:`DEFAULT_REAL_TIME_FACTOR`).

    Raises
    ------
    CommandError
        Before any node starts, for a bags directory that cannot hold the bag or a
        ``ROS_DOMAIN_ID`` that is not a domain id.
    PlantError
        Before any node starts, for a plant and a fidelity that disagree.
    """
    out = sys.stdout if out is None else out
    plant, fidelity = plant_and_fidelity(plant, fidelity)
    if real_time_factor is None:
        real_time_factor = DEFAULT_REAL_TIME_FACTOR[plant]

    def say(line: str) -> None:
        print(line, file=out, flush=True)

    domain_id, domain_origin = demo_domain_id(os.environ)
    bag_parent = check_bags_dir(bags_dir)  # the last check: it may create the directory
    stamp = datetime.datetime.now(datetime.UTC).strftime('%Y%m%dT%H%M%SZ')
    bag_dir = bag_parent / f'demo_{stamp}'
    duration_s = setpoint_s + trajectory_s
    say(f'demo: ROS_DOMAIN_ID={domain_id} ({domain_origin}), '
        f'{DISCOVERY_RANGE_VAR}={os.environ.get(DISCOVERY_RANGE_VAR, "LOCALHOST (default)")}')
    for line in demo_start_lines(plant, real_time_factor, setpoint_s, trajectory_s, fidelity):
        say(line)
    if check_fidelity:
        say(f'demo: check_fidelity: the full model at rtol {CHECK_RTOL:g} runs beside the '
            'simulator, kick by kick, on the spare core; the summary says how far the landings '
            'diverged')
    with StopSignals() as stop:
        live = _run_live(demo_nodes(bag_dir, setpoint_s, real_time_factor, seed, plant,
                                    check_fidelity, fidelity),
                         domain_id, duration_s, real_time_factor, bag_dir, stop, say)
        failures = _report_exits(live.processes, say)
        _report_pace(live.processes, say, real_time_factor)
        offline_rms_rad = (None if stop.requested
                           else _offline_rms_rad(setpoint_s, duration_s, plant, fidelity,
                                                 stop, say))
        problems = live.problems + failures
        problems += _report_bag(bag_dir, setpoint_s, live.simulated_s, say, offline_rms_rad,
                                failures, plant, fidelity)
    say(f'demo: bag {bag_dir}')
    if stop.requested:
        say(f'demo: STOPPED by {stop.name}, exit status {stop.exit_status}'
            + (f'; {"; ".join(problems)}' if problems else ''))
        return stop.exit_status
    if problems:
        say('demo: FAILED: ' + '; '.join(problems))
        return 1
    say('demo: OK: recorder, simulator, reference and controller ran as separate processes '
        f'on domain {domain_id} and exited with 0')
    return 0


def _run_live(nodes: Sequence[NodeSpec], domain_id: int, duration_s: float,
              real_time_factor: float, bag_dir: Path, stop: StopSignals,
              say: Callable[[str], None]) -> LiveRun:
    """Start the nodes (the simulator last, once the controller holds the reference), watch
    the run until ``duration_s`` of simulated time, a timeout or a stop signal, saying its
    progress every few seconds, and stop every node by its PID."""
    from msg_defs.topics import CONTROLLER_STATUS, SURFACE_NORMAL
    from sphere_twin.testing import TopicProbe, TwinTimeoutError

    *others, simulator = nodes
    problems: list[str] = []
    with running_nodes(*others, domain_id=domain_id) as group:
        for process in group.processes:
            say(f'demo: started {process.name} (pid {process.pid})')
        probe = TopicProbe(domain_id, (SURFACE_NORMAL, CONTROLLER_STATUS))
        stop.install()  # over the handlers rclpy installed with the probe's context
        log = RunLog(probe)
        waiting = time.monotonic()
        watch = _Watch(probe, stop, say)
        simulator_started: float | None = None
        try:
            watch.until(log.controller_ready, START_TIMEOUT_S, 'controller holding the reference',
                        lambda: f'waiting for the controller to hold the reference '
                                f'({time.monotonic() - waiting:.0f} s)')
            if not stop.requested:
                process = group.start(simulator.executable, simulator.args)
                say(f'demo: started {process.name} (pid {process.pid})')
                simulator_started = time.monotonic()
                _watch_the_loop(watch, log, duration_s, real_time_factor, bag_dir, say)
        except TwinTimeoutError as error:
            problems.append(str(error).splitlines()[0])
        simulated_s = log.simulated_s()
        if stop.requested:
            say(f'demo: got {stop.name} at {simulated_s:.1f} of {duration_s:g} s simulated: '
                'stopping the nodes, then the summary so far')
        probe.close()
        if simulator_started is not None:
            say(f'demo: ran {time.monotonic() - simulator_started:.1f} s wall from the '
                'simulator\'s start')
        say(f'demo: stopping {" then ".join(p.name for p in reversed(group.processes))} '
            '(SIGINT to each PID)')
    return LiveRun(group.processes, problems, simulated_s)


class _Watch:
    """Spins the demo's probe until a condition, a stop signal or a timeout, saying a
    progress line every few seconds (a long run must never look hung)."""

    def __init__(self, probe: TopicProbe, stop: StopSignals, say: Callable[[str], None]) -> None:
        self.probe, self.stop, self.say = probe, stop, say

    def until(self, done: Callable[[], object], timeout_s: float, what: str,
              progress: Callable[[], str]) -> None:
        from sphere_twin.run_analysis import ProgressClock

        clock = ProgressClock()

        def finished() -> bool:
            if clock.due():
                self.say(f'demo: progress: {progress()}')
            return self.stop.requested or bool(done())

        self.probe.spin_until(finished, timeout_s, what)


def _watch_the_loop(watch: _Watch, log: RunLog, duration_s: float, real_time_factor: float,
                    bag_dir: Path, say: Callable[[str], None]) -> None:
    """Until the first kick, then until ``duration_s`` of simulated time (or a stop signal),
    with the simulated time, the controller's kicks and the bag's size as progress."""
    started = time.monotonic()

    def progress() -> str:
        return (f'{log.simulated_s():.1f} of {duration_s:g} s simulated, {log.kicks()} kicks, '
                f'bag {_bag_bytes(bag_dir) / 1e6:.1f} MB, '
                f'{time.monotonic() - started:.0f} s wall')

    watch.until(lambda: log.kicks() > 0, START_TIMEOUT_S, 'first kick', progress)
    if watch.stop.requested:
        return
    say(f'demo: the loop runs: first kick at {log.simulated_s():.2f} s simulated')
    wall_limit = WALL_MARGIN * duration_s / real_time_factor + START_TIMEOUT_S
    watch.until(lambda: log.simulated_s() >= duration_s, wall_limit,
                f'{duration_s:g} s of simulated time', progress)


def _bag_bytes(bag_dir: Path) -> int:
    """What the recorder has written so far (0 before it made the bag)."""
    return sum(path.stat().st_size for path in bag_dir.glob('*.mcap')) if bag_dir.is_dir() else 0


def _offline_rms_rad(setpoint_s: float, duration_s: float, plant: str, fidelity: str,
                     stop: StopSignals, say: Callable[[str], None]) -> float | None:
    """The offline loop's trajectory RMS error (rad), saying its progress; None if a stop
    signal ended it."""
    from sphere_twin.run_analysis import ProgressClock

    say('demo: the offline loop on the same controller, plant, reference and kick period '
        '(no ROS) ...')
    clock = ProgressClock()

    def on_time(time_s: float) -> None:
        if stop.requested:
            raise _StoppedError
        if clock.due():
            say(f'demo: progress: offline loop at {time_s:.1f} of {duration_s:g} s simulated')

    try:
        offline = offline_loop(setpoint_s, duration_s, plant, on_time, fidelity)
    except _StoppedError:
        say(f'demo: got {stop.name} in the offline loop: no comparison with it')
        return None
    return _trajectory_rms_rad(offline.times_s, offline.errors_rad, setpoint_s)


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


# Below this fraction of the pace asked for, the summary says the pace slipped.
PACE_HELD_FRACTION = 0.95


def _report_pace(processes: Iterable[NodeProcess], say: Callable[[str], None],
                 asked_factor: float) -> None:
    """Say the real-time factor each node saw and the late programmes (those that started
    later than the controller asked: the simulator fell behind), from their farewell lines,
    and whether the simulator held the pace asked for."""
    factors, late, held, checked = [], None, None, ''
    for process in processes:
        text = process.stdout_text()
        found = REAL_TIME_FACTOR_PATTERN.findall(text)
        if found:
            factors.append(f'{process.name} {float(found[-1]):.2f}')
            if process.name == 'simulator':
                held = float(found[-1])
        if process.name == 'simulator' and LATE_PATTERN.search(text):
            late = int(LATE_PATTERN.findall(text)[-1])
        if process.name == 'simulator' and FIDELITY_CHECK_PATTERN.search(text):
            checked = FIDELITY_CHECK_PATTERN.findall(text)[-1]
    say(f'demo: real-time factor: {", ".join(factors)}; late programmes: '
        f'{"unknown" if late is None else late}')
    if checked:
        say(f'demo: fidelity check: {checked}')
    if held is not None and held < PACE_HELD_FRACTION * asked_factor:
        say(f'demo: the pace slipped: asked {asked_factor:g}, the simulator held {held:.2f} '
            '(this machine could not integrate faster; a late programme starts at the next '
            'sample)')


def _trajectory_rms_rad(times_s: ArrayLike, errors_rad: ArrayLike, setpoint_s: float) -> float:
    """RMS of the errors from the trajectory's start on (rad); NaN before it."""
    tracking = np.asarray(times_s) >= setpoint_s
    return (math.sqrt(float(np.mean(np.asarray(errors_rad)[tracking] ** 2))) if tracking.any()
            else math.nan)


def _report_bag(bag_dir: Path, setpoint_s: float, run_end_s: float,
                say: Callable[[str], None], offline_rms_rad: float | None,
                failures: Sequence[str] = (), plant: str = DEFAULT_PLANT,
                fidelity: str = LIVE_FIDELITY) -> list[str]:
    """What the run did, every figure read back from its own bag as `sphere-twin report`
    reads it (never from a node's output: a recorder that died holds less than the run
    did, and figures from two sources would not agree), beside the offline loop's
    trajectory RMS error, and a plot; the problems (an unreadable bag, no normal recorded).

    ``run_end_s`` is the simulated time the demo saw the run reach; a bag that ends well
    before it, or ``failures`` (a node's non-zero exit), is said before the figures. The kicks
    line names ``plant`` and the rung ``fidelity`` it served them from.
    """
    from sphere_twin.bag.reader import BagError
    from sphere_twin.run_analysis import (
        errors_at_decisions_rad,
        errors_rad,
        load_run,
        plot_report,
        unclosed_bag_warning,
    )

    try:
        recorded = load_run(bag_dir)
        times, errors = errors_rad(recorded)
        warning = unclosed_bag_warning(bag_dir, recorded)
    except BagError as error:
        return [str(error)]
    if warning:
        say(f'demo: warning: {warning}')
    if times.size == 0:
        return ['no surface normal crossed between the processes']
    bag_end_s = float(recorded.normal_t_s[-1])
    if failures or bag_end_s < run_end_s - BAG_LAG_S:
        why = f'{"; ".join(failures)}: ' if failures else ''
        say(f'demo: {why}the figures below are what the bag holds, up to {bag_end_s:.1f} s '
            f'simulated (the run reached {run_end_s:.1f} s)')
    plot = plot_report(recorded, bag_dir.parent / f'{bag_dir.name}_error.png',
                       title=f'{bag_dir.name}: setpoint, then eq. (64) from {setpoint_s:g} s')
    kicks = len(recorded.kicks)
    say(f'demo: {kicks} kicks in {bag_end_s:.1f} s simulated '
        f'({kicks / max(bag_end_s, 1e-9):.1f} per second) on the {plant} plant, model '
        f'{fidelity}, from the bag')
    on_setpoint = (times > 0.5 * setpoint_s) & (times < setpoint_s)
    if on_setpoint.any():
        say(f'demo: setpoint: final error {math.degrees(errors[on_setpoint][-1]):.4f} deg')
    # Like for like: the error where the loop decided (settled states), as the offline loop
    # records it; and over every sample, kicks in flight included.
    decided_t_s, decided_errors_rad = errors_at_decisions_rad(recorded)
    rms_rad = _trajectory_rms_rad(decided_t_s, decided_errors_rad, setpoint_s)
    if math.isfinite(rms_rad):
        offline = ('' if offline_rms_rad is None
                   else f' (offline loop: {math.degrees(offline_rms_rad):.3f} deg)')
        say(f'demo: trajectory RMS error {math.degrees(rms_rad):.3f} deg{offline}')
        say(f'demo: trajectory: RMS error over every sample, kicks in flight included, '
            f'{math.degrees(_trajectory_rms_rad(times, errors, setpoint_s)):.3f} deg; final '
            f'error {math.degrees(errors[-1]):.3f} deg')
    say(f'demo: plot {plot}')
    return []


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add the ``demo`` subcommand to the ``sphere-twin`` parser."""
    parser = subparsers.add_parser(
        'demo', help='the closed loop as separate processes, recorded to a bag',
        description='Start recorder, simulator, reference and controller as processes on the '
                    'domain of ROS_DOMAIN_ID, or a fresh one if it is unset (discovery limited '
                    'to localhost), run the Fig. 13 setpoint and then the eq. (64) trajectory, '
                    'stop every node by PID, and report kicks, errors, real-time factor, the '
                    'bag and a plot, all read from the bag. SIGINT or SIGTERM stops the nodes, '
                    'prints the summary so far and exits with 130 or 143.')
    parser.add_argument('--setpoint-s', type=simulated_seconds, default=DEFAULT_SETPOINT_S,
                        help='simulated seconds on the setpoint')
    parser.add_argument('--trajectory-s', type=simulated_seconds, default=DEFAULT_TRAJECTORY_S,
                        help='simulated seconds on the trajectory')
    parser.add_argument('--plant', choices=PLANT_KINDS, default='',
                        help='the simulator\'s plant: the continuous model of §3, or the '
                             'discrete table of kicks (the paper\'s shortcut); default: the '
                             'one --fidelity names, else continuous')
    parser.add_argument('--fidelity', choices=FIDELITIES, default='',
                        help='the rung of the ladder of models the simulator serves kicks '
                             f'from (docs/numerics.md); default: {LIVE_FIDELITY} on the '
                             'continuous plant, table on the discrete one')
    parser.add_argument('--real-time-factor', type=positive_float, default=None,
                        help='simulated seconds per wall second (default: '
                             + ', '.join(f'{v:g} for the {k} plant'
                                         for k, v in DEFAULT_REAL_TIME_FACTOR.items()) + ')')
    parser.add_argument('--bags-dir', default='bags',
                        help='where the bag directory goes (created if missing)')
    parser.add_argument('--seed', type=int, default=0)
    parser.add_argument('--check-fidelity', action='store_true',
                        help=f'run the full model (rtol {CHECK_RTOL:g}) beside the simulator '
                             'on every kick, on the spare core, and say how far the landings '
                             'diverged')
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Entry point of the subcommand; returns the exit code."""
    return run_demo(args.setpoint_s, args.trajectory_s, args.real_time_factor, args.bags_dir,
                    args.seed, plant=args.plant, check_fidelity=args.check_fidelity,
                    fidelity=args.fidelity)
