"""``sphere-twin bench twin``: the live loop over DDS, unpaced, and the simulator's accounts."""

import json
import math

import pytest

from sphere_twin.cli import main
from sphere_twin.twin_bench import LoopCycle, TwinBenchResult, run_twin_bench, summary_lines

pytestmark = pytest.mark.ros

DURATION_S = 3.0


@pytest.fixture(scope='module')
def runs():
    return {plant: run_twin_bench(plant, DURATION_S) for plant in ('discrete', 'continuous')}


@pytest.mark.parametrize('plant', ['discrete', 'continuous'])
def test_the_status_accounts_for_the_run(runs, plant):
    result, farewell = runs[plant]
    assert result.plant == plant
    assert result.simulated_s >= DURATION_S
    assert result.real_time_factor == pytest.approx(result.simulated_s / result.wall_s, rel=1e-3)
    assert result.programmes > 0
    # One sample per 20 ms of simulated time, and the initial one.
    assert result.samples == pytest.approx(result.simulated_s / 0.02 + 1, abs=1)
    assert 0.0 < result.integrating_fraction < 1.0 and 0.0 < result.publishing_fraction < 1.0
    assert 0.0 <= result.other_fraction < 1.0
    assert 0.0 < result.latency_median_ms <= result.latency_max_ms
    assert farewell.startswith('simulator: simulated')


def test_the_physics_costs_integration_time_the_table_does_not(runs):
    continuous, discrete = runs['continuous'][0], runs['discrete'][0]
    assert continuous.integrating_fraction > 5 * discrete.integrating_fraction
    assert continuous.real_time_factor < discrete.real_time_factor
    # The physics takes any programme at any time; only the table refuses overlapping kicks.
    assert continuous.rejected == 0


def test_summary_ends_with_the_headline_and_the_result_round_trips(runs):
    result, _ = runs['continuous']
    lines = summary_lines(result)
    assert lines[-1] == f'twin real-time factor: {result.real_time_factor:.2f} unpaced (continuous)'
    data = result.to_dict()
    assert math.isclose(data['other_fraction'], result.other_fraction)
    assert TwinBenchResult.from_dict(data) == result


def test_cli_writes_the_results_and_prints_the_headline_last(tmp_path, capsys):
    assert main(['bench', 'twin', '--plant', 'discrete', '--duration-s', '1', '--out',
                 str(tmp_path)]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[-1].startswith('twin real-time factor: ') and out[-1].endswith(
        ' unpaced (discrete)')
    data = json.loads((tmp_path / 'twin_discrete.json').read_text())
    assert data['simulated_s'] >= 1.0
    assert (tmp_path / 'twin_discrete.md').read_text().count('twin real-time factor') == 1


def test_the_loop_cycle_is_split_into_delay_settling_and_lead():
    # Kicks decided on samples 40 ms before the starts they ask, started 5 ms late, one every
    # 120 ms simulated and 80 ms wall.
    starts = [0.1 + 0.12 * k for k in range(6)]
    cycle = LoopCycle.measure(starts, [2.0 + 0.08 * k for k in range(6)],
                              [s - 0.04 for s in starts], 0.005)
    assert cycle.simulated_ms == pytest.approx(120.0) and cycle.wall_ms == pytest.approx(80.0)
    assert (cycle.start_delay_ms, cycle.lead_ms) == (pytest.approx(5.0), pytest.approx(40.0))
    assert cycle.start_delay_ms + cycle.settling_ms + cycle.lead_ms == pytest.approx(120.0)
    assert LoopCycle.measure(starts[:2], [0.0, 1.0], starts[:2], 0.0) is None


@pytest.mark.parametrize('plant', ['discrete', 'continuous'])
def test_no_cycle_is_shorter_than_the_kick_window_and_the_lead(runs, plant):
    cycle = runs[plant][0].cycle
    # The controller decides only on a sample at or after the kick's window (60 ms) and asks
    # the next start two sample periods (40 ms) after that sample.
    assert cycle.lead_ms == pytest.approx(40.0)
    assert cycle.simulated_ms >= 100.0 - 1e-6
    assert cycle.settling_ms + cycle.start_delay_ms >= 60.0 - 1e-6
