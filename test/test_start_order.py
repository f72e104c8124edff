"""Simulator, reference and controller started by hand, in every order: the kick cycle is
driven by the simulator's reports, so no programme is refused as overlapping a running kick,
and the controller learns only from kicks that ran to their end."""

import itertools
import re

import pytest

from msg_defs.conversions import programme_events_from_msg, status_values
from msg_defs.programme_events import ProgrammeState
from msg_defs.topics import CONTROLLER_STATUS, PROGRAMME_STATUS
from sphere_twin.processes import parameter_args
from sphere_twin.testing import TopicProbe

pytestmark = pytest.mark.ros

ORDERS = list(itertools.permutations(('simulator', 'reference', 'controller')))
# Every order once; across the six, each pairing of waiting for subscribers and sim time
# (the controller and the reference on /clock) is met at least once.
SETTINGS = [(wait, sim_time) for wait, sim_time in itertools.product((0, 1), (False, True))]
LANDED_KICKS = 8  # kicks that ran to their end before the run is judged
RUN_TIMEOUT_S = 60.0
# The table's kicks move the normal by at most 0.73 deg: eq. (64) entered at A_max (26 deg of
# tilt) keeps the controller kicking for the whole run.
REFERENCE_ARGS = dict(trajectory_start_s=0.0)
SIMULATOR_FAREWELL = re.compile(r'(?P<programmes>\d+) programmes started \(\d+ late\), '
                                r'commands: (?P<rejected>\d+) rejected')
CONTROLLER_FAREWELL = re.compile(r'(?P<kicks>\d+) kicks sent over .*\((?P<landed>\d+) landed, '
                                 r'(?P<cut>\d+) cut, (?P<refused>\d+) refused, '
                                 r'(?P<unanswered>\d+) unanswered, (?P<not_started>\d+) '
                                 r'awaiting its start report, (?P<not_landed>\d+) started and '
                                 r'not yet landed\)')


@pytest.mark.parametrize('k', range(len(ORDERS)),
                         ids=['-'.join(name[0] for name in order) for order in ORDERS])
def test_no_programme_overlaps_and_only_landed_kicks_are_learned_in_any_start_order(ros_nodes,
                                                                                      k):
    order = ORDERS[k]
    wait, sim_time = SETTINGS[k % len(SETTINGS)]
    args = {
        'simulator': parameter_args(plant='discrete', real_time_factor=2.0,
                                    wait_for_subscribers=wait),
        'reference': parameter_args(use_sim_time=sim_time, **REFERENCE_ARGS),
        'controller': parameter_args(use_sim_time=sim_time),
    }
    processes = {name: ros_nodes.start(name, args[name]) for name in order}
    probe = TopicProbe(ros_nodes.domain_id, (CONTROLLER_STATUS, PROGRAMME_STATUS),
                       processes['simulator'])
    statuses = probe.messages[CONTROLLER_STATUS.name]

    def enough_seen():
        # Kicks the probe saw start (it joins late and may miss the first) and kicks the
        # controller says it learned from.
        started = sum(e.state is ProgrammeState.STARTED
                      for m in probe.messages[PROGRAMME_STATUS.name]
                      for e in programme_events_from_msg(m))
        values = [status_values(m.status[0]) for m in statuses[-3:]]
        landed = max((int(v.get('landed', 0)) for v in values), default=0)
        return min(started, landed) >= LANDED_KICKS

    try:
        probe.spin_until(enough_seen, RUN_TIMEOUT_S,
                         f'{LANDED_KICKS} landed kicks ({"-".join(order)}, wait {wait}, '
                         f'sim time {sim_time})')
    finally:
        probe.close()
    ros_nodes.stop_all()
    assert all(p.returncode == 0 for p in processes.values())
    events = [e for m in probe.messages[PROGRAMME_STATUS.name]
              for e in programme_events_from_msg(m)]
    # The reports carry no text (action_msgs): a failure shows the refused events themselves.
    assert [e for e in events if e.state is ProgrammeState.REFUSED] == []
    # Each kick starts only after the one before it has ended. Paired by the programme's
    # number, not by position: the probe joins late, and on a loaded machine its queue
    # (depth 10) can drop a report, which would shift every pair after it.
    starts = {e.number: e.time_s for e in events if e.state is ProgrammeState.STARTED}
    ends = {e.number: e.time_s for e in events if e.state is ProgrammeState.ENDED}
    pairs = [(ends[n], starts[n + 1]) for n in ends if n + 1 in starts]
    assert len(pairs) >= LANDED_KICKS // 2
    assert all(end <= start for end, start in pairs), pairs
    # The books of both ends, from their farewell lines: nothing rejected; every kick the
    # controller sent is in exactly one of its counts, the one in flight at the stop included;
    # the simulator counts the programmes it started: the landed ones and the one the
    # controller heard start, and perhaps the one whose start report the controller had not
    # yet had (or gave up on).
    sim = SIMULATOR_FAREWELL.search(processes['simulator'].stdout_text())
    ctl = CONTROLLER_FAREWELL.search(processes['controller'].stdout_text())
    assert sim and ctl, (processes['simulator'].stdout_text()
                         + processes['controller'].stdout_text())
    started, rejected = int(sim['programmes']), int(sim['rejected'])
    sent, landed, unanswered, not_started, not_landed = (
        int(ctl[k]) for k in ('kicks', 'landed', 'unanswered', 'not_started', 'not_landed'))
    assert rejected == 0 and int(ctl['cut']) == int(ctl['refused']) == 0
    assert not_started + not_landed <= 1
    assert sent == landed + unanswered + not_started + not_landed
    assert landed + not_landed <= started <= landed + not_landed + not_started + unanswered
