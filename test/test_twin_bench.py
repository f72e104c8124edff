"""``sphere-twin bench twin``: the live loop over DDS, unpaced, and the simulator's accounts."""

import json
import math

import pytest

from sphere_sim.kicks.discrete import kick_period_s
from sphere_sim.kicks.lookup_table import LookupTable
from sphere_twin.cli import main
from sphere_twin.twin_bench import LoopCycle, TwinBenchResult, run_twin_bench, summary_lines

# Unpaced, and judged by counts and by the two plants against each other, never by the wall
# clock alone: make test runs these beside the physics tests.
pytestmark = [pytest.mark.ros, pytest.mark.load_tolerant]

DURATION_S = 3.0


@pytest.fixture(scope='module')
def runs():
    return {plant: run_twin_bench(plant, DURATION_S) for plant in ('discrete', 'continuous')}


@pytest.mark.parametrize('plant', ['discrete', 'continuous'])
def test_the_status_accounts_for_the_run(runs, plant):
    result, farewell = runs[plant]
    assert result.plant == plant
    # The rung that served the kicks, as the simulator says it: the plant's own.
    assert result.fidelity == {'discrete': 'table', 'continuous': 'full'}[plant]
    assert result.simulated_s >= DURATION_S
    assert result.real_time_factor == pytest.approx(result.simulated_s / result.wall_s, rel=1e-3)
    assert result.programmes > 0
    # One sample per 10 ms of simulated time (the default 100 Hz), and the initial one.
    assert result.samples == pytest.approx(result.simulated_s / 0.01 + 1, abs=1)
    assert 0.0 < result.integrating_fraction < 1.0 and 0.0 < result.publishing_fraction < 1.0
    assert 0.0 <= result.waiting_fraction < 1.0 and 0.0 <= result.other_fraction < 1.0
    # Publishing runs on its own thread: the simulation thread's shares add up without it.
    assert result.integrating_fraction + result.waiting_fraction + result.other_fraction == \
        pytest.approx(1.0)
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
    assert lines[-1] == (f'twin real-time factor: {result.real_time_factor:.2f} unpaced '
                         '(continuous, full)')
    data = result.to_dict()
    assert math.isclose(data['other_fraction'], result.other_fraction)
    assert TwinBenchResult.from_dict(data) == result


def test_cli_writes_the_results_and_prints_the_headline_last(tmp_path, capsys):
    assert main(['bench', 'twin', '--plant', 'discrete', '--duration-s', '1', '--out',
                 str(tmp_path)]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[-1].startswith('twin real-time factor: ') and out[-1].endswith(
        ' unpaced (discrete, table)')
    data = json.loads((tmp_path / 'twin_discrete.json').read_text())
    assert data['simulated_s'] >= 1.0
    assert (tmp_path / 'twin_discrete.md').read_text().count('twin real-time factor') == 1


def test_the_loop_cycle_is_split_into_delay_settling_and_lead():
    # Kicks asked 10 ms after the samples they were decided on, started 5 ms late, decided
    # again 55 ms after each actual start: one every 70 ms simulated, 80 ms wall.
    asked = [0.1 + 0.07 * k for k in range(6)]
    started = [a + 0.005 for a in asked]
    decisions = [a - 0.01 for a in asked]
    cycle = LoopCycle.measure(asked, started, [2.0 + 0.08 * k for k in range(6)], decisions)
    assert cycle.simulated_ms == pytest.approx(70.0) and cycle.wall_ms == pytest.approx(80.0)
    assert (cycle.start_delay_ms, cycle.lead_ms) == (pytest.approx(5.0), pytest.approx(10.0))
    assert cycle.settling_ms == pytest.approx(55.0)
    assert cycle.start_delay_ms + cycle.settling_ms + cycle.lead_ms == pytest.approx(70.0)
    assert LoopCycle.measure(asked[:2], started[:2], [0.0, 1.0], decisions[:1]) is None


@pytest.mark.parametrize('plant', ['discrete', 'continuous'])
def test_the_cycle_is_the_kick_period_and_one_sample_from_the_reported_start(runs, plant):
    result = runs[plant][0]
    cycle = result.cycle
    # The controller decides on the first sample a kick period (the shipped table's full kick
    # settles in 38 ms: 40 ms) after the reported start and asks the next start one sample
    # period (10 ms) after that sample. Unpaced, the simulator may run past the asked start
    # before the programme arrives; the cycle then starts from the actual start and waits the
    # full kick period again, never less.
    period_ms = 1e3 * kick_period_s(LookupTable.load_current())
    assert cycle.lead_ms == pytest.approx(10.0)
    assert cycle.settling_ms >= period_ms - 1e-6
    assert cycle.simulated_ms >= period_ms + 10.0 - 1e-6
    # Nothing is refused as overlapping a kick that is still running.
    assert result.rejected == 0
