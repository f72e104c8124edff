"""The model side of the protocol's thresholds (sphere_sim.fitting.thresholds): the threshold of
one pulse by the protocol's rule agrees with an independent rule, moves the way the physics
says with the parameters that set it, and a recorded bracket becomes a residual; the fit of a
threshold recovers the parameter that made it (sphere_sim.fitting.joint_fit)."""

import itertools
import math

import numpy as np
import pytest
import yaml
from physics_helpers import ground_contact_threshold_v

from sphere_sim.fitting.observations import KickObservation
from sphere_sim.fitting.protocol import ProbeBracket, probe_brackets, probe_programme
from sphere_sim.fitting.thresholds import (
    MODEL_ERROR_V,
    MODEL_RESOLUTION_V,
    OUTCOME_STEP_V,
    OUTCOME_WINDOW_V,
    ThresholdError,
    ThresholdObservation,
    model_threshold_v,
    non_monotone,
    observations_of,
    rises_once,
    switches_text,
)

LEVEL = (0.0, 0.0, 1.0)
BEAM = (3,)
WIDTH_S = 5e-3
SHORT_S = 1.5e-3
K_Z = 'beam.stiffness_z_n_per_m'
K_PHI = 'beam.stiffness_phi_nm_per_rad'
DAMPING = 'beam.damping_phi_nms_per_rad'
STATIC_FRICTION = 'friction.static_coefficient'


@pytest.fixture(scope='module')
def calibrated():
    from sphere_sim.model.parameters import load_parameter_set

    return load_parameter_set('calibrated')


def test_the_protocols_rule_finds_the_threshold_the_beam_touching_down_finds(calibrated):
    # Searched from a guess 1.5 V below it: the search gallops up as needed.
    by_rule = model_threshold_v(calibrated, BEAM, WIDTH_S, LEVEL, 45.0)
    by_contact = ground_contact_threshold_v(calibrated, BEAM[0], WIDTH_S, 44.0, 49.0)
    assert abs(by_rule - by_contact) < 0.1


def test_softer_suspension_lowers_the_threshold_and_more_damping_raises_a_short_pulses(
        calibrated):
    def threshold(params, width_s, guess):
        return model_threshold_v(params, BEAM, width_s, LEVEL, guess)

    long_pulse = threshold(calibrated, WIDTH_S, 46.5)
    softer = threshold(calibrated.replace(**{K_Z: 0.9 * calibrated.get(K_Z)}), WIDTH_S,
                       46.5)
    assert softer < long_pulse - 10 * MODEL_RESOLUTION_V
    short_pulse = threshold(calibrated, SHORT_S, 56.2)
    damped = threshold(calibrated.replace(**{DAMPING: 1.3 * calibrated.get(DAMPING)}), SHORT_S,
                       56.2)
    assert damped > short_pulse + 10 * MODEL_RESOLUTION_V


class SteppedProbe:
    """A probe whose pulses pull in from ``threshold_v`` up, counting the pulses."""

    def __init__(self, threshold_v):
        self.threshold_v, self.pulses = threshold_v, 0

    def pulls_in(self, amplitude_v):
        self.pulses += 1
        return amplitude_v >= self.threshold_v


@pytest.mark.parametrize('guess_v', [44.237, 44.23, 44.25, 44.19, 44.31, 40.0, 49.5, 0.0, 89.0])
def test_the_models_threshold_is_its_lattice_cell_wherever_the_search_starts(guess_v):
    from sphere_sim.fitting.thresholds import _search

    stepped = SteppedProbe(44.2371)
    assert _search(stepped, guess_v, MODEL_RESOLUTION_V) == pytest.approx(44.235, abs=1e-9)
    # A guess d cells off costs at most two pulses and two per doubling of d.
    cells = max(abs(guess_v - 44.235) / MODEL_RESOLUTION_V, 1.0)
    assert stepped.pulses <= 2 + 2 * math.ceil(math.log2(cells)) + 1


def test_a_guess_in_the_right_cell_costs_its_two_ends_and_no_threshold_reads_the_limit():
    from msg_defs.device import VOLTAGE_LIMIT_V
    from sphere_sim.fitting.thresholds import UNPREDICTED_STEP_V, _search

    stepped = SteppedProbe(44.2371)
    _search(stepped, 44.2371, MODEL_RESOLUTION_V)
    assert stepped.pulses == 2
    # From a guess that is no prediction, 4 V off, a wide first step gallops in fewer pulses
    # to the same cell.
    narrow, wide = SteppedProbe(44.2371), SteppedProbe(44.2371)
    assert (_search(narrow, 48.2, MODEL_RESOLUTION_V)
            == _search(wide, 48.2, MODEL_RESOLUTION_V, first_step_v=UNPREDICTED_STEP_V))
    assert wide.pulses < narrow.pulses
    # A lattice from an origin (a recorded bracket's low end): the cell [44.233, 44.243).
    for guess_v in (44.24, 44.1, 45.0):
        assert _search(SteppedProbe(44.2371), guess_v, MODEL_RESOLUTION_V,
                       origin_v=44.003) == pytest.approx(44.238, abs=1e-9)
    assert _search(SteppedProbe(math.inf), 50.0, MODEL_RESOLUTION_V) == VOLTAGE_LIMIT_V


def test_a_threshold_is_predicted_from_the_points_searched_near_it():
    from sphere_sim.fitting.thresholds import PREDICTION_RADIUS_U, predicted_thresholds_v

    rng = np.random.default_rng(3)
    points = 0.5 + 0.02 * rng.standard_normal((6, 2))
    slope = np.array([[3.0, -1.0], [0.5, 2.0]])  # two thresholds, affine in u
    values = 44.0 + (points - 0.5) @ slope
    u = np.array([0.51, 0.49])
    np.testing.assert_allclose(predicted_thresholds_v(points, values, u),
                               44.0 + (u - 0.5) @ slope, atol=1e-9)
    # No more points than parameters: the nearest one's.
    np.testing.assert_allclose(predicted_thresholds_v(points[:2], values[:2], u),
                               values[np.argmin(np.linalg.norm(points[:2] - u, axis=1))])
    # Nothing searched near: no prediction (the search starts at the recorded bracket).
    assert predicted_thresholds_v(points, values, u + 2 * PREDICTION_RADIUS_U) is None
    assert predicted_thresholds_v(np.zeros((0, 2)), np.zeros((0, 2)), u) is None


def probe(beams, width_s, amplitude_v, before, after):
    times, volts = probe_programme(beams, width_s, amplitude_v).segments()
    unit = [np.asarray(n, float) / np.linalg.norm(n) for n in (before, after)]
    return KickObservation(0.0, times, volts, unit[0], unit[1], 60, 60)


def test_rising_once_is_no_pulse_pulling_in_below_one_that_does_not():
    assert rises_once([(1.0, False), (2.0, False), (3.0, True)])
    assert rises_once([(3.0, True), (1.0, False)])  # in any order
    assert rises_once([(1.0, False)]) and rises_once([(1.0, True)])
    window = [(1.0, False), (2.0, True), (3.0, False), (4.0, True)]
    assert not rises_once(window)
    assert switches_text(window) == 'pulls in at 2.00 V, not at 3.00 V, pulls in at 4.00 V'


def test_a_pair_at_short_pulses_switches_three_times_and_is_left_out(calibrated):
    """At the start values (calibrated), paper_b's pair of beams 1+2 at 1.5 ms, from level:
    its pulses pull in from about 49 V, not from about 52 V, and again from about 54 V (the
    device's bisection found 54.28-54.46 V); the same pair at 5 ms rises once."""
    from sphere_sim.kicks.engine import SerialEngine

    short = ThresholdObservation((1, 2), SHORT_S, 54.28, 54.46, LEVEL)
    long = ThresholdObservation((1, 2), WIDTH_S, 40.68, 40.85, LEVEL)
    scans = non_monotone(calibrated, (long, short), SerialEngine())
    assert scans.keys() == {1}
    outcomes = scans[1]
    assert len(outcomes) == round(2 * OUTCOME_WINDOW_V / OUTCOME_STEP_V) + 1
    assert not rises_once(outcomes)
    switches = [a for (_, p), (a, q) in itertools.pairwise(outcomes) if p != q]
    assert len(switches) == 3
    assert 47.0 < switches[0] < switches[1] < switches[2] < 56.0


def test_a_bracket_keeps_where_the_sphere_rested_before_its_end_probes():
    tilt = 2e-3
    probes = [probe(BEAM, WIDTH_S, 40.0, (0, 0, 1), (0, 0, 1)),  # not pulled in
              probe(BEAM, WIDTH_S, 50.0, (0, 0, 1), (tilt, 0, 1)),  # pulled in
              probe(BEAM, WIDTH_S, 45.0, (tilt, 0, 1), (tilt, 0, 1)),  # not: the low end
              probe(BEAM, WIDTH_S, 47.5, (tilt, 0, 1), (2 * tilt, 0, 1))]  # the high end
    (bracket,) = probe_brackets(probes, 1e-5)
    assert (bracket.not_pulled_in_v, bracket.pulled_in_v) == (45.0, 47.5)
    # Both end probes started from the tilted rest, not from the level one of the first two.
    assert bracket.normal_before[0] == pytest.approx(tilt, rel=1e-3)


def test_a_bracket_becomes_a_residual_weighed_by_its_width():
    bracket = ProbeBracket(BEAM, WIDTH_S, 44.0, 44.2, 8, LEVEL)
    obs = ThresholdObservation.from_bracket(bracket)
    assert obs.middle_v == pytest.approx(44.1)
    # A uniform 0.2 V wide, the model's own 0.01 V and its error, in quadrature.
    assert obs.std_v == pytest.approx(math.sqrt((0.2 ** 2 + MODEL_RESOLUTION_V ** 2) / 12
                                                + MODEL_ERROR_V ** 2))
    one_sided = ProbeBracket(BEAM, WIDTH_S, None, 44.2, 3, LEVEL)
    with pytest.raises(ThresholdError, match='one side'):
        ThresholdObservation.from_bracket(one_sided)
    used, left = observations_of([bracket, one_sided])
    assert len(used) == 1 and left == [one_sided]


def test_the_fit_of_one_threshold_recovers_the_stiffness_that_made_it(calibrated):
    """A bracket 0.2 V wide around the threshold of a device with a softer suspension: the
    fit's profile interval holds the device's stiffness, is determined, and excludes the start
    set's."""
    from sphere_sim.fitting.identification import fit_parameters
    from sphere_sim.fitting.joint_fit import fit_jointly

    device = calibrated.replace(**{K_Z: 0.85 * calibrated.get(K_Z)})
    made = model_threshold_v(device, BEAM, WIDTH_S, LEVEL, 44.5)
    low = math.floor(made / 0.2) * 0.2  # a bisection's grid
    obs = [ThresholdObservation(BEAM, WIDTH_S, low, low + 0.2, LEVEL)]
    (fit,) = fit_parameters(calibrated, [K_Z])
    result = fit_jointly(calibrated, [fit], None, obs, max_evaluations=60,
                         starts_per_parameter=2, descents=1)
    (estimate,) = result.estimates
    assert estimate.determined, estimate.note
    assert estimate.contains(device.get(K_Z))
    assert not estimate.contains(calibrated.get(K_Z))
    assert abs(result.threshold_residuals[0]) < 1.0


def test_a_fit_that_does_not_reach_the_noise_determines_nothing(calibrated):
    """The same threshold recorded twice, 3 V apart: no stiffness meets both brackets, so the
    fit's residuals are not the noise, and its profile, however narrow, is not an interval."""
    from sphere_sim.fitting.identification import fit_parameters
    from sphere_sim.fitting.joint_fit import fit_jointly
    from sphere_sim.fitting.profile_fit import reaches_the_noise

    device = calibrated.replace(**{K_Z: 0.85 * calibrated.get(K_Z)})
    low = math.floor(model_threshold_v(device, BEAM, WIDTH_S, LEVEL, 44.5) / 0.2) * 0.2
    obs = [ThresholdObservation(BEAM, WIDTH_S, low, low + 0.2, LEVEL),
           ThresholdObservation(BEAM, WIDTH_S, low + 3.0, low + 3.2, LEVEL)]
    (fit,) = fit_parameters(calibrated, [K_Z])
    result = fit_jointly(calibrated, [fit], None, obs, max_evaluations=60,
                         starts_per_parameter=2, descents=1)
    (estimate,) = result.estimates
    assert not reaches_the_noise(result.chi2, 2, 1)
    assert result.profile.intervals[0].determined  # narrow: the profile alone would say so
    assert not estimate.determined
    assert 'does not reach the noise' in estimate.note
    # The closed form: chi-square's 99.9 % point with one degree of freedom is 10.83.
    assert reaches_the_noise(10.8, 2, 1) and not reaches_the_noise(10.9, 2, 1)


def test_identify_thresholds_prints_each_parameters_status_and_writes_the_fitted_file(
        tmp_path, monkeypatch, capsys):
    """The command's wiring, the fit replaced by a known answer: the brackets of the bag are
    read, a one-sided one is said to be left out, each parameter is printed with its interval
    and status, an undetermined one with its range, and the fitted file loads as a parameter
    set holding the fitted values."""
    from pathlib import Path

    import sphere_sim.fitting.joint_fit as joint_fit
    import sphere_twin.protocol_bag as protocol_bag
    from sphere_sim.fitting.observations import Observations
    from sphere_sim.fitting.profile_fit import ProfileFit
    from sphere_sim.model.parameters import load_parameter_set
    from sphere_twin import cli

    brackets = (ProbeBracket(BEAM, WIDTH_S, 44.0, 44.2, 8, LEVEL),
                ProbeBracket((1, 2), WIDTH_S, None, 70.0, 8, LEVEL))
    monkeypatch.setattr(protocol_bag, 'protocol_of',
                        lambda run: protocol_bag.ProtocolResults(brackets, (), 9.4e-4))
    seen = {}

    def known_answer(params, fits, kicks, thresholds, workers, scheduler, checkpoint, progress,
                     max_evaluations):
        seen['kicks'], seen['thresholds'], seen['limit'] = kicks, thresholds, max_evaluations
        estimates = (joint_fit.ProfileEstimate(fits[0].path, 34.3, 34.1, 34.6, fits[0].low,
                                               fits[0].high, True, 'narrow'),
                     joint_fit.ProfileEstimate(fits[1].path, 5e-9, 2.5e-9, 1e-8, fits[1].low,
                                               fits[1].high, False,
                                               'its profile reaches a bound of the range'),
                     joint_fit.ProfileEstimate(fits[2].path, 0.5, 0.2, 1.0, fits[2].low,
                                               fits[2].high, False,
                                               'its profile reaches a bound of the range'))
        profile = ProfileFit(np.zeros(2), 0.5, (), 12, False, False)
        none = np.zeros((0, 2))
        pair = ThresholdObservation((1, 2), SHORT_S, 54.28, 54.46, LEVEL)
        return joint_fit.JointFitResult(estimates, 0.49, 0.0, Observations((), 0.0), (),
                                        tuple(thresholds), np.array([0.7]), np.array([44.14]),
                                        none, none, 12, profile, non_monotone=(
                                            (pair, 'pulls in at 47.9 V, not at 51.4 V'),))

    monkeypatch.setattr(joint_fit, 'fit_jointly', known_answer)
    bag = Path(__file__).resolve().parents[1] / 'bags' / 'synthetic_device'
    out = tmp_path / 'fitted.yaml'
    status = cli.main(['identify', str(bag), '--thresholds', '--params', 'calibrated',
                       '--fit', K_Z, DAMPING, STATIC_FRICTION, '--max-evaluations', '7',
                       '--out', str(out)])
    printed = capsys.readouterr().out
    assert status == 0
    assert seen['limit'] == 7 and seen['kicks'] is None
    assert [o.beams for o in seen['thresholds']] == [BEAM]
    assert 'left out beams 1+2, 5 ms' in printed
    assert 'beam 3, 5 ms: recorded 44.00-44.20 V, model 44.14 V (+0.70 sd)' in printed
    assert ('left out beams 1+2, 1.5 ms (recorded 54.28-54.46 V): at the start values its '
            'pulses switch more than once around it (pulls in at 47.9 V, not at 51.4 V)'
            in printed)
    assert f'{K_Z}: 34.3, 95 % profile interval [34.1, 34.6]' in printed
    assert ': determined' in printed
    assert f'{DAMPING}: 5e-09' in printed and 'undetermined (its profile reaches a bound' in printed
    # Thresholds alone: the friction is undetermined, and the line says which experiment
    # would determine it; the beams' damping has its experiment, so no such word.
    (friction_line,) = [line for line in printed.splitlines()
                        if line.startswith(f'{STATIC_FRICTION}:')]
    assert friction_line.endswith('the recordings hold no kicks, which determine it')
    assert not any(line.startswith(DAMPING) and 'hold no' in line
                   for line in printed.splitlines())
    fitted = load_parameter_set(str(out))
    assert fitted.get(K_Z) == pytest.approx(34.3) and fitted.get(DAMPING) == pytest.approx(5e-9)
    report = yaml.safe_load(out.read_text())['identification']
    assert report['left_out_thresholds'] == [{
        'step': 'beams 1+2, 1.5 ms', 'recorded_v': [54.28, 54.46],
        'switches': 'pulls in at 47.9 V, not at 51.4 V'}]


def test_the_threshold_bench_counts_each_starts_pulses_and_the_cells_it_missed(monkeypatch,
                                                                               tmp_path):
    """``bench thresholds``' rows with the simulation replaced by stepped probes (each
    threshold known): a start in the right cell costs its two ends, one off costs more, a wide
    first step costs more a few cells off, and every start ends in the first one's cell."""
    from sphere_sim.fitting.thresholds import SearchCost, _search
    from sphere_twin.commands import bench_thresholds

    known_v = {44.0: 44.1371, 46.0: 46.2049}  # bracket low end -> the model's threshold

    def stepped_cost(params, observation, guess_v, first_step_v=MODEL_RESOLUTION_V):
        stepped = SteppedProbe(known_v[observation.low_v])
        value = _search(stepped, guess_v, MODEL_RESOLUTION_V, observation.low_v, first_step_v)
        return SearchCost(value, stepped.pulses, 0.1 * stepped.pulses)

    monkeypatch.setattr(bench_thresholds, 'search_cost', stepped_cost)
    observations = [ThresholdObservation(BEAM, WIDTH_S, low, low + 0.2, LEVEL)
                    for low in known_v]
    rows = bench_thresholds.start_rows(None, observations)
    assert [r.elsewhere for r in rows] == [0] * 5
    middle, wide, right, next_cell, far = rows
    assert right.pulses == 2 * len(observations)
    assert middle.pulses > next_cell.pulses > right.pulses and far.pulses > next_cell.pulses
    assert wide.pulses > middle.pulses  # a few cells off, the wide first step overshoots
    bench_thresholds.write_results(rows, tmp_path / 'paper_b', 2, tmp_path / 'out.md')
    table = (tmp_path / 'out.md').read_text()
    assert f'| the right cell | {right.pulses} | {right.wall_s:.1f} | 0 |' in table


def test_the_threshold_bench_refuses_a_bag_without_its_truth(tmp_path, capsys):
    from sphere_twin import cli

    status = cli.main(['bench', 'thresholds', '--bag', str(tmp_path), '--out', str(tmp_path)])
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert status == 2
    assert line.startswith('sphere-twin bench thresholds: error: ') and 'no truth.yaml' in line
