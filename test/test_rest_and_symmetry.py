"""Rest equilibrium (§4.1) and the symmetry of the device."""

import numpy as np

from sphere_sim.model.parameters import load_parameter_set
from sphere_sim.studies import validation

REST_IMBALANCE = 1e-6  # of the weight per tip


def test_rest_is_an_equilibrium_with_tips_on_the_front_edge_and_stays_put():
    rest = validation.rest_report(load_parameter_set('calibrated'), duration_s=1.0)
    assert rest.force_imbalance < REST_IMBALANCE
    assert np.all(rest.front_gaps_m < 0) and np.all(rest.rear_gaps_m > 5e-6)
    assert rest.tilt_drift_rad < 1e-9
    assert rest.position_drift_m < 1e-9


def test_literal_table_rests_with_tips_above_the_front_edge():
    rest = validation.rest_report(load_parameter_set('table_a1'), duration_s=0.1)
    assert rest.force_imbalance < REST_IMBALANCE
    assert np.all(rest.front_gaps_m > 0)


def test_equal_voltages_give_no_rotation():
    tilt, lift = validation.symmetric_pulse_tilt()
    assert lift > 1e-6  # the kick happened
    assert tilt < 1e-9


def test_mirrored_programme_gives_mirrored_motion():
    mismatch, excursion = validation.mirror_mismatch()
    assert excursion > 1e-4  # the sphere did rotate
    assert mismatch < 1e-6 * excursion + 1e-9
