"""Calibration: the joint fit to the pull-in, and the calibrated set it wrote."""

import json
import math
from pathlib import Path

import numpy as np
import pytest

from sphere_sim.fitting.calibration import bisect, with_value
from sphere_sim.kicks.design import KickDesign, simulate_kick
from sphere_sim.model.assembly import assemble
from sphere_sim.model.initial_state import rest_state
from sphere_sim.model.parameters import UncertainParameter, load_parameter_set
from sphere_sim.model.scene import load_scene

RESULTS = Path(__file__).parents[1] / 'bench' / 'results'
# Three parameters fitted jointly to the pull-in, and one held at an estimate.
STAND_IN_SPECS = (
    UncertainParameter('beam.stiffness_z_n_per_m', 20.0, 70.0, 'suspension', 'fig4_threshold'),
    UncertainParameter('beam.stiffness_phi_nm_per_rad', 1e-6, 1.68e-5, 'torsion', 'fig4_threshold'),
    UncertainParameter('beam.ground_z_m', -11e-6, -9e-6, 'spacer', 'fig4_threshold'),
    UncertainParameter('friction.static_coefficient', 0.1, 0.8, 'dry pair', 'estimate'),
)


def stand_in_threshold_v(params):
    """A threshold rising with k_z and the gap, falling with k_phi, as the model's does."""
    b = params.beam
    return (40.0 + 0.5 * (b.stiffness_z_n_per_m - 35.0)
            - 2.0 * math.log(b.stiffness_phi_nm_per_rad / 4e-6)
            + 5e6 * (-b.ground_z_m - 10e-6))


def test_bisect_finds_the_target_geometrically():
    seen = []
    value, observed, history = bisect(math.log10, 1e-3, 10.0, -0.5, 1e-3, geometric=True,
                                      progress=lambda v, o: seen.append(v))
    assert value == pytest.approx(10 ** -0.5, rel=3e-3)
    assert abs(observed + 0.5) < 1e-3
    assert [v for v, _ in history] == seen
    assert len(history) < 20


def test_bisect_stops_at_the_nearer_end_of_a_range_that_cannot_reach_the_target():
    value, observed, history = bisect(lambda v: v, 0.0, 1.0, 5.0, 0.01)
    assert (value, observed) == (1.0, 1.0)  # the range is not stretched
    assert len(history) == 2
    value, observed, _ = bisect(lambda v: -v, 0.0, 1.0, 5.0, 0.01)
    assert (value, observed) == (0.0, -0.0)


def test_tied_parameters_move_together():
    spec = UncertainParameter('friction.coulomb', 0.1, 0.8, 'dry pair', 'estimate',
                              tied=('friction.stribeck',))
    moved = with_value(load_parameter_set('calibrated'), spec, 0.37)
    assert {moved.get(path) for path in spec.paths} == {0.37}


def test_committed_kick_design_belongs_to_the_current_parameters():
    """The committed optimised kick was optimised for the calibrated set as it is now."""
    optimised = json.loads((RESULTS / 'kick_optimization.json').read_text())
    assert optimised['parameter_digest'] == load_parameter_set('calibrated').digest()
    design = KickDesign.load(RESULTS / 'kick_optimization.json')
    model = assemble(load_scene('rest'))
    result, _ = simulate_kick(model, np.array([0.0, 0.0, 1.0]), design.programme(),
                              x_rest=rest_state(model))
    d = result.normal[:2]
    rotation = math.degrees(math.asin(np.hypot(*d)))
    assert rotation == pytest.approx(optimised['rotation_deg'], rel=1e-3)
    assert math.degrees(math.atan2(d[1], d[0])) == pytest.approx(-45.0, abs=0.5)


def test_the_joint_fit_meets_the_pull_in_with_the_smallest_move(monkeypatch):
    """On a stand-in threshold the joint fit reaches the target, keeps every value inside its
    range and off its bounds, leaves the estimate alone, and moves less (in range
    coordinates) than any single parameter fitted alone would."""
    from sphere_sim.fitting import calibration
    monkeypatch.setattr(calibration, 'threshold_v', stand_in_threshold_v)
    cal = load_parameter_set('calibrated')
    reference = load_parameter_set('table_a1')
    params, fits = calibration.calibrate(cal, STAND_IN_SPECS, reference=reference)
    assert [f.spec.path for f in fits] == [s.path for s in STAND_IN_SPECS[:3]]
    assert all(f.reached for f in fits)
    assert stand_in_threshold_v(params) == pytest.approx(calibration.TARGET_THRESHOLD_V,
                                                         abs=calibration.FIT_TOLERANCE_V)
    assert params.friction.static_coefficient == cal.friction.static_coefficient
    moves = []
    for spec in STAND_IN_SPECS[:3]:
        coordinate = calibration.range_coordinate(spec, params.get(spec.path))
        assert calibration.RANGE_MARGIN <= coordinate <= 1.0 - calibration.RANGE_MARGIN
        start = calibration.start_coordinate(spec, reference.get(spec.path))
        moves.append(coordinate - start)
    # k_phi's table value (20 uN m/rad) lies outside its range: the fit starts at its centre.
    assert calibration.start_coordinate(STAND_IN_SPECS[1], 20e-6) == 0.5
    # Each coordinate moved, none alone: the move is shared along the gradient.
    assert sum(1 for m in moves if abs(m) > 1e-3) == 3


def test_calibrate_reports_a_target_its_ranges_cannot_reach(monkeypatch):
    """A target beyond what the ranges give ends the fit at the margins, marked unreached: the
    ranges are never stretched."""
    from sphere_sim.fitting import calibration
    monkeypatch.setattr(calibration, 'threshold_v',
                        lambda params: stand_in_threshold_v(params) - 40.0)
    cal = load_parameter_set('calibrated')
    params, fits = calibration.calibrate(cal, STAND_IN_SPECS,
                                         reference=load_parameter_set('table_a1'))
    assert not any(f.reached for f in fits)
    assert all(f.at_margin for f in fits)
    for spec in STAND_IN_SPECS[:3]:
        assert spec.low < params.get(spec.path) < spec.high


def test_the_calibrated_set_is_the_joint_fit_of_its_declared_ranges():
    """The shipped values sit inside their ranges, off their bounds, and give the target
    (the pull-in with the sphere on), with the beams alone lower (§4.1)."""
    from sphere_sim.fitting import calibration
    cal = load_parameter_set('calibrated')
    fitted = [s for s in cal.uncertain if s.target == 'fig4_threshold']
    assert {s.path for s in fitted} == {'beam.stiffness_z_n_per_m',
                                        'beam.stiffness_phi_nm_per_rad', 'beam.ground_z_m'}
    for spec in fitted:
        coordinate = calibration.range_coordinate(spec, cal.get(spec.path))
        assert calibration.RANGE_MARGIN <= coordinate <= 1.0 - calibration.RANGE_MARGIN
