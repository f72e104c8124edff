"""``sphere-twin experiment BAG_DIR``: the experiment protocol (``sphere_sim.fitting.protocol``)
sent over the device's topics and recorded.

Drives a device already running on the domain of ``ROS_DOMAIN_ID`` (hardware, or a simulator
the user started), or with ``--twin`` starts the simulator itself (lockstep, or paced with
``--real-time-factor``) on the domain of ``ROS_DOMAIN_ID``, or a fresh one if it is unset.
Starts the recorder on BAG_DIR, then runs the loop every driver of the protocol shares
(:func:`sphere_twin.protocol_run.run_protocol`): each probe of a threshold search goes out on
``/beams/pulse_program`` stamped with its start on the device's clock, the resting samples on
``/sphere/surface_normal`` decide whether it pulled in, and the bisection goes on; ramps
likewise; the step that needs a measurement the wire lacks is said not runnable; the kicks
last. It prints each bracket as it is decided, then what the bag reads back
(:func:`sphere_twin.protocol_bag.read_protocol`) and whether the two agree.

A protocol that could command more than the voltage limit is refused before anything starts.
SIGINT (Ctrl-C) or SIGTERM stops the nodes it started by their PIDs and exits with 130 or 143.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, TextIO

from sphere_sim.kicks.discrete import NOISE_STUDY_STD_RAD
from sphere_twin.commands.options import (
    CommandError,
    add_params_option,
    non_negative_float,
    number_in_range,
    output_directory,
)

if TYPE_CHECKING:
    from sphere_sim.fitting.protocol import Protocol
    from sphere_sim.model.parameters import ParameterSet
    from sphere_twin.commands.demo import StopSignals
    from sphere_twin.processes import NodeProcess, NodeSpec
    from sphere_twin.testing import TopicProbe

# --quick: one threshold search, beam 3 with 5 ms pulses at 1 V, in a bracket around the
# paper's device's threshold (46.55 V on `calibrated`, 44.17 V on paper_b): four probes.
QUICK_BEAM = 3
QUICK_WIDTH_S = 5e-3
QUICK_BRACKET_V = (36.0, 52.0)
QUICK_RESOLUTION_V = 1.0
# Subscribers the twin waits for on /sphere/surface_normal before its time starts: the recorder
# and the command's own probe.
TWIN_NORMAL_SUBSCRIBERS = 2
CONNECT_TIMEOUT_S = 60.0
ROS_DEFAULT_DOMAIN_ID = 0


def quick_protocol() -> Protocol:
    from sphere_sim.fitting.protocol import Protocol, ThresholdSearch

    return Protocol((ThresholdSearch((QUICK_BEAM,), QUICK_WIDTH_S, QUICK_BRACKET_V,
                                     QUICK_RESOLUTION_V),))


def with_bracket(protocol: Protocol, bracket_v: tuple[float, float]) -> Protocol:
    """``protocol`` with every threshold search's bracket replaced by ``bracket_v``."""
    import dataclasses

    from sphere_sim.fitting.protocol import Protocol, ThresholdSearch

    return Protocol(tuple(dataclasses.replace(step, bracket_v=bracket_v)
                          if isinstance(step, ThresholdSearch) else step
                          for step in protocol.steps))


def device_domain_id(environ: Mapping[str, str]) -> tuple[int, str]:
    """The domain of a device already running: ``ROS_DOMAIN_ID``, else ROS's default 0."""
    from sphere_twin.commands.demo import MAX_ROS_DOMAIN_ID
    from sphere_twin.node_runtime.ros_env import DOMAIN_ID_VAR

    given = environ.get(DOMAIN_ID_VAR, '').strip()
    if not given:
        return ROS_DEFAULT_DOMAIN_ID, f'{DOMAIN_ID_VAR} unset: ROS\'s default'
    if not given.isdigit() or int(given) > MAX_ROS_DOMAIN_ID:
        raise CommandError(f'{DOMAIN_ID_VAR}={given!r} is not a ROS domain id (an integer from '
                           f'0 to {MAX_ROS_DOMAIN_ID})')
    return int(given), 'from the environment'


def twin_node(real_time_factor: float, params: str, noise_std_rad: float,
              seed: int) -> NodeSpec:
    """The simulator ``--twin`` starts: the continuous model, lockstep unless paced."""
    from sphere_twin.processes import NodeSpec, parameter_args

    return NodeSpec('simulator', tuple(parameter_args(
        plant='continuous', **({'params': params} if params else {}), seed=seed,
        noise_std_rad=float(noise_std_rad),
        lockstep=real_time_factor == 0.0, real_time_factor=float(real_time_factor or 1.0),
        wait_for_subscribers=TWIN_NORMAL_SUBSCRIBERS)))


def run_experiment(bag_dir: str | os.PathLike[str], protocol: Protocol, twin: bool = False,
                   real_time_factor: float = 0.0, params: str = '',
                   noise_std_rad: float = NOISE_STUDY_STD_RAD, seed: int = 0,
                   out: TextIO | None = None) -> int:
    """Run ``protocol`` over the topics into ``bag_dir``; 0 if it ran and the bag reads back
    to the brackets decided on the wire, 1 if not, 128 + the signal's number if stopped.

    Raises
    ------
    CommandError
        Before any node starts: a protocol over the voltage limit, an existing ``bag_dir``, a
        ``ROS_DOMAIN_ID`` that is no domain id.
    """
    from sphere_sim.fitting.protocol import ProtocolError, check_protocol
    from sphere_twin.commands.demo import StopSignals, demo_domain_id
    from sphere_twin.processes import NodeSpec, parameter_args

    stream = sys.stdout if out is None else out

    def say(line: str) -> None:
        print(line, file=stream, flush=True)

    try:
        check_protocol(protocol)
    except ProtocolError as error:
        raise CommandError(str(error)) from None
    bag = Path(bag_dir)
    if bag.exists():
        raise CommandError(f'{bag} exists: give a new bag directory')
    if twin:
        domain_id, origin = demo_domain_id(os.environ)
    else:
        domain_id, origin = device_domain_id(os.environ)
    nodes = [NodeSpec('recorder', tuple(parameter_args(output_dir=str(bag))))]
    if twin:
        nodes.append(twin_node(real_time_factor, params, noise_std_rad, seed))
        pace = 'lockstep' if real_time_factor == 0.0 else f'paced at {real_time_factor:g}'
        say(f'experiment: the twin (continuous plant, {pace}, parameters '
            f'{params or "of the scene"}, sensor noise {noise_std_rad:.3g} rad) on domain '
            f'{domain_id} ({origin})')
    else:
        say(f'experiment: the device on domain {domain_id} ({origin})')
    say(f'experiment: {len(protocol.steps)} steps: '
        + '; '.join(step.label for step in protocol.steps))
    with StopSignals() as stop:
        brackets, problems, processes, samples = _run_live(nodes, domain_id, protocol, stop,
                                                           say)
        if stop.requested:
            say(f'experiment: STOPPED by {stop.name}: stopped '
                + ', '.join(f'{p.name} (pid {p.pid})' for p in processes)
                + f'; exit status {stop.exit_status}')
            return stop.exit_status
    problems += [f'{p.name} exited with {p.returncode}' for p in processes
                 if p.returncode != 0]
    problems += _report_bag(bag, brackets, samples, say)
    if problems:
        say('experiment: FAILED: ' + '; '.join(problems))
        return 1
    return 0


def _run_live(nodes: Sequence[NodeSpec], domain_id: int, protocol: Protocol,
              stop: StopSignals, say: Callable[[str], None],
              ) -> tuple[list[tuple[str, tuple[float | None, float | None]]], list[str],
                         list[NodeProcess], int]:
    """Start the nodes, run the protocol through the probe, stop the nodes by their PIDs.
    Returns the brackets decided on the wire, the problems, the processes and the samples."""
    from msg_defs.topics import PROGRAMME_STATUS, SURFACE_NORMAL
    from sphere_twin.processes import running_nodes
    from sphere_twin.protocol_run import bracket_line, not_run_line, run_protocol
    from sphere_twin.protocol_wire import DeviceError, StoppedError, TopicDevice
    from sphere_twin.testing import TopicProbe, TwinTimeoutError

    problems: list[str] = []
    brackets: list[tuple[str, tuple[float | None, float | None]]] = []
    samples = 0
    with running_nodes(*nodes, domain_id=domain_id) as group:
        for process in group.processes:
            say(f'experiment: started {process.name} (pid {process.pid})')
        probe = TopicProbe(domain_id, (SURFACE_NORMAL, PROGRAMME_STATUS))
        stop.install()  # over the handlers rclpy installed with the probe's context

        def stopped() -> bool:
            """A stop signal; DeviceError if a node it started has exited."""
            for process in group.processes:
                if not process.running():
                    last = (process.stderr_text().strip().splitlines() or [''])[-1]
                    raise DeviceError(f'{process.name} exited with {process.returncode}'
                                      + (f': {last}' if last else ''))
            return stop.requested

        device = TopicDevice(probe, stopped)
        started = time.monotonic()
        try:
            _connect(probe, stopped)
            say('experiment: the recorder and the device listen; running the protocol')

            def on_bracket(label: str, bracket: tuple[float | None, float | None]) -> None:
                brackets.append((label, bracket))
                say(f'experiment: {bracket_line(label, bracket)} (decided on the wire)')

            record = run_protocol(device, protocol, lambda label: say(f'experiment: {label}'),
                                  on_bracket)
            for label, needs in record.not_run:
                say(f'experiment: {not_run_line(label, needs)}')
        except StoppedError:
            pass
        except (TwinTimeoutError, DeviceError) as error:
            problems.append(str(error).splitlines()[0])
        samples = device.samples
        say(f'experiment: {samples} samples, {device.programmes} programmes, {device.holds} '
            f'0 V holds in {time.monotonic() - started:.1f} s wall; stopping '
            + ' then '.join(f'{p.name} (pid {p.pid})' for p in reversed(group.processes)))
        probe.close()
    return brackets, problems, group.processes, samples


def _connect(probe: TopicProbe, stopped: Callable[[], bool]) -> None:
    """Until the recorder records the normal and the programmes and the device takes both
    commands from this process: a programme sent before would be lost to one of them."""
    from msg_defs.topics import PULSE_PROGRAM, SURFACE_NORMAL, VOLTAGE_COMMAND
    from sphere_twin.protocol_wire import StoppedError

    programmes, holds = probe.publisher(PULSE_PROGRAM), probe.publisher(VOLTAGE_COMMAND)
    node = probe.node

    def recorder_listens(topic_name: str) -> bool:
        return any(info.node_name == 'recorder'
                   for info in node.get_subscriptions_info_by_topic(topic_name))

    def ready() -> bool:
        if stopped():
            raise StoppedError
        return (recorder_listens(SURFACE_NORMAL.name) and recorder_listens(PULSE_PROGRAM.name)
                and programmes.get_subscription_count() >= 2
                and holds.get_subscription_count() >= 1)

    probe.spin_until(ready, CONNECT_TIMEOUT_S,
                     'recorder and device listening on the command topics')


def _report_bag(bag: Path, brackets: Sequence[tuple[str, tuple[float | None, float | None]]],
                samples: int, say: Callable[[str], None]) -> list[str]:
    """What the bag reads back, as the synthetic recorder prints it, and whether its brackets
    are the ones decided on the wire."""
    from sphere_twin.bag.reader import BagError
    from sphere_twin.protocol_bag import read_protocol
    from sphere_twin.protocol_run import result_lines

    try:
        results = read_protocol(bag)
    except BagError as error:
        return [str(error)]
    say(f'experiment: wrote {bag}: {samples} samples; sensor noise '
        f'{results.noise_std_rad:.3g} rad per axis, read back:')
    for line in result_lines(results, ()):
        say(line)
    read = [(b.not_pulled_in_v, b.pulled_in_v) for b in results.brackets]
    decided = [bracket for _, bracket in brackets]
    if read != decided:
        return [f'the bag reads back brackets {read}, the wire decided {decided}']
    say(f'experiment: OK: the bag reads back the {len(read)} bracket(s) decided on the wire')
    return []


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add the ``experiment`` subcommand to the ``sphere-twin`` parser."""
    parser = subparsers.add_parser(
        'experiment', help='run the experiment protocol over the device\'s topics, recorded',
        description='Run the experiment protocol (pull-in thresholds by bisection on pulse '
                    'trains, slow ramps, kicks; docs/identification.md) over the topics of a '
                    'device running on the domain of ROS_DOMAIN_ID, or with --twin of a '
                    'simulator it starts (on ROS_DOMAIN_ID, or a fresh domain if unset); '
                    'record it to BAG_DIR and print each bracket, decided on the wire and read '
                    'back from the bag. A protocol over the voltage limit is refused before '
                    'anything starts; SIGINT or SIGTERM stops the nodes it started and exits '
                    'with 130 or 143.')
    parser.add_argument('bag_dir', metavar='BAG_DIR', type=output_directory,
                        help='the bag to record (a new directory)')
    parser.add_argument('--quick', action='store_true',
                        help=f'one threshold search only: beam {QUICK_BEAM}, '
                             f'{QUICK_WIDTH_S * 1e3:g} ms pulses, {QUICK_BRACKET_V[0]:g} to '
                             f'{QUICK_BRACKET_V[1]:g} V at {QUICK_RESOLUTION_V:g} V')
    parser.add_argument('--bracket', type=non_negative_float, nargs=2, metavar=('LOW_V', 'HIGH_V'),
                        help='the threshold searches\' bracket (V) instead of the protocol\'s')
    parser.add_argument('--twin', action='store_true',
                        help='start the simulator (continuous model) and drive it, instead of '
                             'a device already running (on ROS_DOMAIN_ID, or a fresh domain '
                             'if it is unset)')
    parser.add_argument('--real-time-factor', type=number_in_range(0.0, 100.0, 'the twin\'s '
                                                                   'pace; 0 is lockstep'),
                        default=0.0,
                        help='with --twin: run it paced at this factor (default 0: lockstep, '
                             'time advances only with the commands)')
    add_params_option(parser, default=None,
                      help='with --twin: its parameter set, a shipped name or a YAML file '
                           '(default: the scene\'s, calibrated)')
    parser.add_argument('--noise-std-rad', type=number_in_range(0.0, 0.1, 'rad per axis'),
                        default=NOISE_STUDY_STD_RAD,
                        help='with --twin: its sensor noise per axis (default: the noise '
                             f'study\'s {NOISE_STUDY_STD_RAD:.3g} rad)')
    parser.add_argument('--seed', type=int, default=0, help='with --twin: its noise seed')
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Entry point of the subcommand; returns the exit code."""
    from sphere_sim.fitting.protocol import DEFAULT_PROTOCOL

    if not args.twin and (args.params is not None or args.real_time_factor):
        raise CommandError('--params and --real-time-factor describe the twin: give --twin')
    protocol = quick_protocol() if args.quick else DEFAULT_PROTOCOL
    if args.bracket is not None:
        protocol = with_bracket(protocol, tuple(args.bracket))
    params = '' if args.params is None else twin_params_arg(args.params, args.bag_dir)
    return run_experiment(args.bag_dir, protocol, args.twin, args.real_time_factor,
                          params, args.noise_std_rad, args.seed)


def twin_params_arg(params: ParameterSet, bag_dir: Path) -> str:
    """What the simulator's ``params`` takes for ``params``: a shipped set's name, or else a
    file beside the bag holding the set whole (``<BAG_DIR>_params.yaml``)."""
    from sphere_twin.commands.identify import set_reference

    return set_reference(params, bag_dir.with_name(f'{bag_dir.name}_params.yaml'))
