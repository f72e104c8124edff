"""Fig. 4: pull-in threshold of 5 ms pulses on all four beams with the sphere on."""

from functools import lru_cache

import numpy as np
import pytest

from sphere_sim.integrate.solve import simulate
from sphere_sim.model.assembly import assemble
from sphere_sim.model.initial_state import rest_state
from sphere_sim.model.scene import load_scene
from sphere_sim.studies.pullin import all_beams_pulse, pull_in

# The dynamic threshold (a 5 ms step, slower than the beam periods of about 0.3 ms, with
# strong torsional damping) must sit within this fraction of the quasi-static fold.
DYNAMIC_VS_STATIC_MARGIN = 0.03


@lru_cache
def _thresholds(parameter_set):
    return pull_in(load_scene('four_beam_pulse').replace(parameter_set=parameter_set))


@pytest.mark.parametrize('parameter_set', ['calibrated', 'table_a1'])
def test_dynamic_threshold_agrees_with_quasi_static_estimate(parameter_set):
    result = _thresholds(parameter_set)
    assert result.dynamic_v == pytest.approx(result.quasi_static_v, rel=DYNAMIC_VS_STATIC_MARGIN)


def test_calibrated_threshold_lies_in_the_papers_band():
    assert 40.0 < _thresholds('calibrated').dynamic_v < 45.0


def test_literal_table_pulls_in_well_below_the_papers_band():
    # A finding, not a failure: Table A1 read literally does not reproduce Fig. 4.
    assert _thresholds('table_a1').dynamic_v < 38.0


def test_literal_table_pulls_in_where_an_independent_implementation_does():
    """Table A1 read literally, nothing fitted: an independent implementation of §3 put its
    pull-in at 32.7 V. The quasi-static fold agrees to 0.1 V; the 5 ms pulse's dynamic threshold
    lies within the dynamic-to-static margin above it."""
    result = _thresholds('table_a1')
    assert result.quasi_static_v == pytest.approx(32.7, abs=0.1)
    assert 32.7 <= result.dynamic_v < 32.7 * (1 + DYNAMIC_VS_STATIC_MARGIN)


def test_sphere_flies_at_70_volts():
    model = assemble(load_scene('four_beam_pulse'))
    x0 = rest_state(model)
    traj = simulate(model, x0, 0.015, all_beams_pulse(model, 70.0), rtol=1e-6,
                    sample_period_s=2e-5)
    gaps = np.array([model.sphere_gaps(traj.x[:, i]).min() for i in range(traj.t.size)])
    airborne = gaps > 0
    assert np.any(airborne)
    # A finite interval: many consecutive samples, then it lands again.
    runs = np.diff(np.flatnonzero(np.diff(np.concatenate([[0], airborne.astype(int), [0]]))))
    assert runs[::2].max() * 2e-5 > 0.5e-3
    assert not airborne[-1] or np.count_nonzero(airborne) < airborne.size
