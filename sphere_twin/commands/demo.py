"""``sphere-twin demo``: run the nodes as separate processes and show that messages cross.

The nodes to run are :data:`DEMO_NODES` and the traffic that must arrive is
:data:`REQUIRED_TOPICS`; the closed loop replaces those two and keeps the rest.
"""

import argparse
import os
import sys
import time

from msg_defs.ros_env import DISCOVERY_RANGE_VAR
from msg_defs.topics import SURFACE_NORMAL
from sphere_twin.monitor_summary import parse_summaries
from sphere_twin.processes import (
    POLL_PERIOD_S,
    NodeSpec,
    fresh_domain_id,
    running_nodes,
)

DEFAULT_DURATION_S = 5.0
# Started in this order, stopped in reverse: the monitor goes first and so counts everything.
DEMO_NODES = (NodeSpec('simulator'), NodeSpec('monitor'))
# Topics the monitor must have received at least one message on.
REQUIRED_TOPICS = (SURFACE_NORMAL.name,)


def _positive_seconds(text):
    value = float(text)
    if not value > 0:
        raise argparse.ArgumentTypeError(f'must be > 0 s, got {text}')
    return value


def _run_for(group, duration_s):
    """Let the nodes run for ``duration_s``; return early if one exits or on Ctrl-C."""
    deadline = time.monotonic() + duration_s
    try:
        while time.monotonic() < deadline:
            if not all(p.running() for p in group.processes):
                return 'a node exited early'
            time.sleep(POLL_PERIOD_S)
    except KeyboardInterrupt:
        return 'interrupted'
    return None


def run_demo(duration_s=DEFAULT_DURATION_S, nodes=DEMO_NODES, required_topics=REQUIRED_TOPICS,
             out=None):
    """Start ``nodes`` in a fresh domain, run them, stop them, report.

    Parameters
    ----------
    duration_s : float
        How long the nodes run (s), start-up included.
    nodes : sequence of NodeSpec
        What to start, in order.
    required_topics : sequence of str
        Topics whose monitor summary must show at least one message.
    out : file-like, optional
        Where to print; ``sys.stdout`` by default.

    Returns
    -------
    int
        0 if messages crossed on every required topic and every node exited with 0, else 1.
    """
    out = sys.stdout if out is None else out

    def say(line):
        print(line, file=out, flush=True)

    domain_id = fresh_domain_id()
    say(f'demo: ROS_DOMAIN_ID={domain_id}, '
        f'{DISCOVERY_RANGE_VAR}={os.environ.get(DISCOVERY_RANGE_VAR, "LOCALHOST (default)")}')
    with running_nodes(*nodes, domain_id=domain_id) as group:
        for process in group.processes:
            say(f'demo: started {process.name} (pid {process.pid})')
        say(f'demo: running for {duration_s:g} s')
        early = _run_for(group, duration_s)
        if early:
            say(f'demo: stopping early: {early}')
        order = ' then '.join(p.name for p in reversed(group.processes))
        say(f'demo: stopping {order} (SIGINT to each PID)')
        group.stop_all()

    received = {}
    for process in group.processes:
        for line in (process.stderr_text() + process.stdout_text()).splitlines():
            say(f'  {process.name:>9} | {line}')
        received.update(parse_summaries(process.stdout_text()))
    for process in reversed(group.processes):
        say(f'demo: stopped {process.name} (pid {process.pid}), exit code {process.returncode}')

    problems = [f'no messages crossed on {topic}' for topic in required_topics
                if not received.get(topic)]
    problems += [f'{p.name} exited with {p.returncode}' for p in group.processes
                 if p.returncode != 0]
    if problems:
        say('demo: FAILED: ' + '; '.join(problems))
        return 1
    counts = ', '.join(f'{received[topic]} messages on {topic}' for topic in required_topics)
    names = ', '.join(p.name for p in group.processes)
    say(f'demo: OK: {counts} crossed between separate processes ({names}) '
        f'on domain {domain_id}; all exited with 0')
    return 0


def register(subparsers):
    """Add the ``demo`` subcommand to the ``sphere-twin`` parser."""
    parser = subparsers.add_parser(
        'demo', help='run simulator and monitor as separate processes and count messages',
        description='Start the simulator and the monitor as two processes on a fresh ROS '
                    'domain (discovery limited to localhost), let them run, stop both by '
                    'PID, and report. Exits non-zero if no messages crossed.')
    parser.add_argument('--duration-s', type=_positive_seconds, default=DEFAULT_DURATION_S,
                        help=f'how long the nodes run, s (default {DEFAULT_DURATION_S:g})')
    parser.set_defaults(func=run)


def run(args):
    """Entry point of the subcommand; returns the exit code."""
    return run_demo(duration_s=args.duration_s)
