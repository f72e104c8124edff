"""The simulator as a separate process over DDS: bad input, lockstep determinism, kicks."""

import math

import numpy as np
import pytest
from test_nodes_in_process import BAD_PROGRAMMES, BAD_VOLTAGES

from msg_defs.topics import PULSE_PROGRAM, VOLTAGE_COMMAND
from sphere_sim.kicks.discrete import kick_period_s
from sphere_sim.kicks.lookup_table import LookupTable
from sphere_sim.model.rotations import angle_between
from sphere_sim.twin.report_limit import REPORTS_PER_WINDOW
from sphere_twin.testing import lockstep_twin

pytestmark = pytest.mark.ros


def test_a_kick_over_dds_lands_where_the_table_says(twin):
    start = twin.wait_for_normal()
    settled = twin.kick(action=0, intensity=1.0)
    expected = LookupTable.load_current().kick(start, 0, 1.0).normal
    assert angle_between(settled, expected) < 1e-12
    assert angle_between(settled, start) > math.radians(0.01)


def test_no_bad_command_crashes_the_simulator_or_reaches_the_plant(twin):
    start = twin.wait_for_normal()
    for msg in BAD_VOLTAGES:
        twin.send_raw(VOLTAGE_COMMAND, msg)
    for msg in BAD_PROGRAMMES:
        twin.send_raw(PULSE_PROGRAM, msg)
    bad = len(BAD_VOLTAGES) + len(BAD_PROGRAMMES)
    twin.spin_until(lambda: int(twin.status().get('rejected', 0)) >= bad,
                    what=f'{bad} rejections counted')
    # Each is counted; the first REPORTS_PER_WINDOW of a second are reported one by one.
    twin.spin_until(lambda: len(twin.rejections) >= REPORTS_PER_WINDOW, what='reports')
    assert all(message.startswith('rejected /beams/') for message in twin.rejections)
    assert len(twin.rejections) <= bad
    assert twin.process.running()
    # Nothing moved, and a valid kick afterwards still works.
    np.testing.assert_array_equal(twin.samples[-1][1], start)
    assert angle_between(twin.kick(action=2, intensity=1.0), start) > math.radians(0.01)


def _run(seed):
    with lockstep_twin(plant='discrete', seed=seed, noise_std_rad=math.radians(0.02)) as client:
        client.wait_for_normal()
        for action, intensity in ((0, 1.0), (1, 0.6), (3, 0.8)):
            client.kick(action, intensity)
        return [(t, n.tolist()) for t, n in client.samples]


def test_lockstep_runs_with_the_same_seed_are_identical():
    first, second = _run(seed=3), _run(seed=3)
    # Idle repeats of the last sample depend on wall time: compare the distinct samples.
    distinct = [dict(first), dict(second)]
    assert distinct[0] == distinct[1]
    # The initial sample and three kick periods (the shipped table's: 40 ms) at 100 Hz.
    period_samples = round(kick_period_s(LookupTable.load_current()) / 0.01)
    assert len(distinct[0]) == 1 + 3 * period_samples


def test_a_healthy_twin_reports_its_status_every_second(twin):
    twin.wait_for_normal()
    # One at its first sample (a recording from the start then holds it), then one a second.
    twin.spin_until(lambda: len(twin.diagnostics) >= 3, timeout_s=6.0,
                    what='the first status and two more')
    assert twin.rejections == []
    status = twin.status()
    assert int(status['samples']) >= 1 and int(status['rejected']) == 0
    assert float(status['wall_time_s']) > 1.0
    assert {'real_time_factor', 'integrating_fraction', 'publishing_fraction',
            'waiting_for_publishing_fraction', 'late', 'cut',
            'programme_latency_median_ms'} <= status.keys()
