"""Calibration: the fitting procedure, and the calibrated set against Fig. 5's kick."""

import json
import math
from pathlib import Path

import numpy as np
import pytest

from sphere_sim.kicks.calibration import KICK_TOLERANCE_DEG, TARGET_KICK_DEG, bisect, with_value
from sphere_sim.kicks.design import KickDesign, simulate_kick
from sphere_sim.model.assembly import assemble
from sphere_sim.model.initial_state import rest_state
from sphere_sim.model.parameters import UncertainParameter, load_parameter_set
from sphere_sim.model.scene import load_scene

RESULTS = Path(__file__).parents[1] / 'bench' / 'results'
# Two parameters fitted to the two observations, and one held at an estimate.
STAND_IN_SPECS = (
    UncertainParameter('beam.stiffness_phi_nm_per_rad', 1e-6, 1.68e-5, 'torsion', 'fig4_threshold'),
    UncertainParameter('friction.coulomb', 0.1, 0.8, 'dry pair', 'fig5_kick',
                       tied=('friction.stribeck',)),
    UncertainParameter('friction.presliding_m', 2e-10, 2e-8, 'Mindlin', 'estimate'),
)


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
    cal = load_parameter_set('calibrated')
    spec = next(u for u in cal.uncertain if u.tied)
    moved = with_value(cal, spec, 0.37)
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


def test_calibrate_fits_each_parameter_to_its_own_target(monkeypatch):
    """The whole procedure on stand-in observations: the threshold falls with k_phi and the
    kick falls with the friction coefficient, and each depends a little on the other parameter,
    so the first pass is checked and, if it moved, repeated."""
    from sphere_sim.kicks import calibration
    def threshold_v(params):
        return 45.0 - 0.8e6 * params.beam.stiffness_phi_nm_per_rad + 0.5 * params.friction.coulomb

    def kick_deg(params, workers=1):
        mu = params.friction.coulomb
        assert params.friction.stribeck == mu  # tied
        return 0.8 - 0.6 * mu + 1e4 * params.beam.stiffness_phi_nm_per_rad

    monkeypatch.setattr(calibration, 'threshold_v', threshold_v)
    monkeypatch.setattr(calibration, 'kick_deg', kick_deg)
    cal = load_parameter_set('calibrated')
    params, fits, checks = calibration.calibrate(cal, STAND_IN_SPECS)
    assert [f.spec.target for f in fits] == ['fig4_threshold', 'fig5_kick']
    assert all(f.reached for f in fits)
    assert params.friction.presliding_m == cal.friction.presliding_m  # an estimate stays
    for observed, target, tolerance in checks:
        assert abs(observed - target) < tolerance
    assert threshold_v(params) == pytest.approx(calibration.TARGET_THRESHOLD_V,
                                                abs=calibration.FIT_TOLERANCE_V)
    assert kick_deg(params) == pytest.approx(TARGET_KICK_DEG, abs=KICK_TOLERANCE_DEG)
    for spec in STAND_IN_SPECS:
        assert spec.low <= params.get(spec.path) <= spec.high


def test_calibrate_reports_a_target_its_range_cannot_reach(monkeypatch):
    """A target outside what the range gives ends the fit at the nearer end, marked unreached,
    and the other fit still runs: the range is never stretched."""
    from sphere_sim.kicks import calibration
    monkeypatch.setattr(calibration, 'threshold_v',
                        lambda params: 43.0 - 1e5 * params.beam.stiffness_phi_nm_per_rad)
    monkeypatch.setattr(calibration, 'kick_deg',
                        lambda params, workers=1: 0.9 - 0.6 * params.friction.coulomb)
    cal = load_parameter_set('calibrated')
    params, fits, _ = calibration.calibrate(cal, STAND_IN_SPECS)
    threshold_fit, kick_fit = fits
    assert not threshold_fit.reached
    assert threshold_fit.value == threshold_fit.spec.low  # the end nearest to 44 V
    assert kick_fit.reached
    assert params.beam.stiffness_phi_nm_per_rad == threshold_fit.spec.low
