"""One misfit of a protocol's kicks and thresholds (sphere_sim.fitting.joint_fit): its residuals
are the kicks' whitened and the thresholds' in standard deviations, each simulated by the same
functions a kicks-only or a thresholds-only fit uses; its evaluations resume from a checkpoint;
and the protocol's probes and ramps are never read as kicks."""

import numpy as np
import pytest

from sphere_sim.fitting.identification import (
    Evaluator,
    fit_parameters,
    kick_end_normal,
)
from sphere_sim.fitting.joint_fit import JointMisfit
from sphere_sim.fitting.observations import KickObservation, Observations
from sphere_sim.fitting.protocol import friction_kicks, probe_programme, ramp_programme
from sphere_sim.fitting.thresholds import ThresholdObservation, model_threshold_v
from sphere_sim.kicks.engine import SerialEngine

LEVEL = np.array([0.0, 0.0, 1.0])
# A kick of the shipped table (the low pair held, the high pair's corners pulsed), as the
# protocol's friction step sends it.
KICK_TIMES_S = np.array([0.0, 0.00077386, 0.00245824, 0.00684731])
KICK_VOLTS = np.array([[0.0, 35.0, 35.0, 0.0], [73.42808042, 35.0, 35.0, 73.42808042],
                       [0.0, 35.0, 35.0, 0.0], [0.0, 0.0, 0.0, 0.0]])
K_Z = 'beam.stiffness_z_n_per_m'


def unit(v):
    v = np.asarray(v, dtype=float)
    return v / np.linalg.norm(v)


def observation(times_s, volts, before, after, time_s=0.0):
    return KickObservation(time_s, np.asarray(times_s, float), np.asarray(volts, float),
                           unit(before), unit(after), 50, 50)


@pytest.fixture(scope='module')
def calibrated():
    from sphere_sim.model.parameters import load_parameter_set

    return load_parameter_set('calibrated')


def test_probes_and_ramps_are_not_read_as_kicks():
    probe = probe_programme((3,), 5e-3, 44.0).segments()
    ramp = ramp_programme((3,), 20.0, 30.0, 65.0).segments()
    kicks = Observations((observation(*probe, LEVEL, LEVEL, 0.0),
                          observation(*ramp, LEVEL, LEVEL, 2.0),
                          observation(KICK_TIMES_S, KICK_VOLTS, LEVEL, [1e-3, 0, 1], 6.0),
                          observation(KICK_TIMES_S, KICK_VOLTS, [1e-3, 0, 1], [2e-3, 0, 1],
                                      7.0)),
                         1e-3, 0, (0, 1, 2))
    left = friction_kicks(kicks)
    assert [k.time_s for k in left.kicks] == [6.0, 7.0]
    # The stretch the two kicks share stays shared; those with the probe and ramp go.
    assert left.shared == (0,)


def test_the_joint_misfit_is_the_kicks_whitened_then_the_thresholds_in_sd(calibrated,
                                                                        tmp_path):
    """At the start values, each residual is what the kicks' and the thresholds' own functions
    give, weighed as each kind's noise says; a rerun reads the evaluation back from the
    checkpoint without simulating, and a checkpoint of other thresholds is not read."""
    kicks = Observations((observation(KICK_TIMES_S, KICK_VOLTS, LEVEL, [1e-3, -1e-3, 1]),), 9e-4)
    threshold = ThresholdObservation((3,), 5e-3, 46.4, 46.6, (0.0, 0.0, 1.0))
    fits = fit_parameters(calibrated, [K_Z])
    u = np.array([fits[0].to_unit(calibrated.get(K_Z))])
    checkpoint = tmp_path / 'fit.partial.jsonl'
    ev = Evaluator(calibrated, kicks, fits, SerialEngine(), checkpoint=checkpoint,
                   thresholds=[threshold])
    r = JointMisfit(ev)(u)
    assert (ev.simulated, ev.searched) == (1, 1)

    end = kick_end_normal(calibrated, kicks.kicks[0])
    expected_kick = kicks.whitener() @ (end - kicks.kicks[0].normal_after)[:2]
    model_v = model_threshold_v(calibrated, (3,), 5e-3, (0.0, 0.0, 1.0), 46.5,
                                origin_v=threshold.low_v)
    assert r.shape == (3,)
    np.testing.assert_allclose(r[:2], expected_kick, rtol=1e-9)
    assert r[2] == pytest.approx((model_v - threshold.middle_v) / threshold.std_v, rel=1e-9)
    # The bracket holds the model's own threshold (46.55 V on `calibrated`).
    assert abs(r[2]) < 2.0

    again = Evaluator(calibrated, kicks, fits, SerialEngine(), checkpoint=checkpoint,
                      thresholds=[threshold])
    assert again.resumed == 1
    np.testing.assert_array_equal(JointMisfit(again)(u), r)
    assert (again.simulated, again.searched) == (0, 0)
    other = Evaluator(calibrated, kicks, fits, SerialEngine(), checkpoint=checkpoint,
                      thresholds=[ThresholdObservation((3,), 5e-3, 46.2, 46.4, LEVEL)])
    assert other.resumed == 0


def test_a_threshold_near_one_searched_starts_at_its_predicted_cell(calibrated, monkeypatch):
    """The second of two nearby points searches each threshold from the cell the first one's
    threshold predicts: a few pulses, not the seven of a search from the recorded bracket's
    middle, and the same cell a search from that middle finds."""
    from sphere_sim.fitting import thresholds

    thresholds.clear_cache()  # an earlier test may have searched the first point
    pulses = []
    pulls_in = thresholds._Probe.pulls_in
    monkeypatch.setattr(thresholds._Probe, 'pulls_in',
                        lambda probe, amplitude_v: pulses.append(amplitude_v)
                        or pulls_in(probe, amplitude_v))
    threshold = ThresholdObservation((3,), 5e-3, 46.4, 46.6, (0.0, 0.0, 1.0))
    fits = fit_parameters(calibrated, [K_Z])
    u = fits[0].to_unit(calibrated.get(K_Z))
    ev = Evaluator(calibrated, Observations((), 0.0), fits, SerialEngine(),
                   thresholds=[threshold])
    ev(np.array([u]))
    from_middle = len(pulses)
    near = np.array([u + 2e-4])  # k_z 0.025 % stiffer: the threshold moves by some 6 mV
    (predicted_v,) = ev.predicted_thresholds_v(near)
    assert predicted_v == ev(np.array([u]))[0]  # one point searched: its threshold
    # A second evaluator (the joint fit's, after the search on the thresholds alone) predicts
    # from the first one's searches too.
    joint = Evaluator(calibrated, Observations((), 0.0), fits, SerialEngine(),
                      thresholds=[threshold], predicted_from=(ev,))
    assert joint.predicted_thresholds_v(near) == predicted_v
    assert Evaluator(calibrated, Observations((), 0.0), fits, SerialEngine(),
                     thresholds=[threshold]).predicted_thresholds_v(near) is None
    (value_v,) = ev(near)
    assert len(pulses) - from_middle <= 3 < from_middle
    thresholds.clear_cache()
    params = calibrated.replace(**{K_Z: fits[0].from_unit(float(near[0]))})
    assert value_v == model_threshold_v(params, (3,), 5e-3, (0.0, 0.0, 1.0),
                                        threshold.middle_v, origin_v=threshold.low_v)


def test_a_threshold_whose_pulses_switch_more_than_once_is_left_out_of_the_fit(calibrated,
                                                                                monkeypatch):
    """The scan before the fit (replaced here by its answer) leaves the first threshold out:
    the search sees only the second, and the result names the first with its switches."""
    from sphere_sim.fitting import joint_fit
    from sphere_sim.fitting.profile_fit import ProfileFit, ProfileInterval

    kept = ThresholdObservation((3,), 5e-3, 46.4, 46.6, (0.0, 0.0, 1.0))
    switching = ThresholdObservation((1, 2), 1.5e-3, 54.28, 54.46, (0.0, 0.0, 1.0))
    scan = ((47.0, False), (48.0, True), (52.0, False), (55.0, True))
    monkeypatch.setattr(joint_fit, 'non_monotone', lambda params, thresholds, engine, rtol: {
        i: scan for i, t in enumerate(thresholds) if t is switching})
    seen = []

    def fit_at_start(misfit, dim, start, **kwargs):
        seen.append(misfit.ev.thresholds)
        return ProfileFit(np.asarray(start), 0.0, (ProfileInterval(0, 0.4, 0.6, False, False,
                                                                   True, ()),), 1, False, False)

    monkeypatch.setattr(joint_fit, 'fit_profiles', fit_at_start)
    result = joint_fit.fit_jointly(calibrated, fit_parameters(calibrated, [K_Z]), None,
                                   [switching, kept], workers=SerialEngine())
    assert seen == [(kept,)]
    assert result.thresholds == (kept,) and len(result.model_thresholds_v) == 1
    assert result.non_monotone == ((switching, 'pulls in at 48.00 V, not at 52.00 V, pulls '
                                                'in at 55.00 V'),)
    with pytest.raises(joint_fit.IdentificationError, match='nothing left to fit'):
        joint_fit.fit_jointly(calibrated, fit_parameters(calibrated, [K_Z]), None,
                              [switching], workers=SerialEngine())


def test_the_protocol_study_counts_what_is_determined_and_the_truths_covered(tmp_path,
                                                                           monkeypatch, capsys):
    """``synthetic study --protocol``: the recording and the fit stubbed with known answers
    (each interval around the truth but the last, which misses it; the first narrow, the
    others wide), the study fits what the device names, prints each parameter's standing and
    ends with the count the issue asks, also written into the table."""
    import sphere_sim.fitting.joint_fit as joint_fit
    import sphere_twin.commands.identify as identify_command
    import sphere_twin.commands.synthetic as synthetic
    from sphere_sim.fitting.profile_fit import ProfileFit
    from sphere_twin import cli
    from sphere_twin.synthetic_device import PAPER_DEVICES

    device = {d.name: d for d in PAPER_DEVICES}['paper_b']
    threshold = ThresholdObservation((3,), 5e-3, 44.0, 44.2, (0.0, 0.0, 1.0))
    monkeypatch.setattr(synthetic, 'record_protocol_bag', lambda device, out: out.mkdir())
    monkeypatch.setattr(identify_command, 'read_recording',
                        lambda bag: identify_command.Recording(Observations((), 9e-4),
                                                               [threshold], []))
    asked = []

    def known_answer(params, fits, kicks, thresholds, engine, scheduler, checkpoint, progress,
                     max_evaluations):
        asked.append(([f.path for f in fits], max_evaluations))
        truth = device.truth(params)
        estimates = []
        for i, f in enumerate(fits):
            true = truth.get(f.path)
            centre = true if i < len(fits) - 1 else true * 1.5
            spread = 1.01 if i == 0 else 1.3
            estimates.append(joint_fit.ProfileEstimate(f.path, centre, centre / spread,
                                                       centre * spread, f.low, f.high, i == 0,
                                                       'stub'))
        none = np.zeros((0, 2))
        return joint_fit.JointFitResult(tuple(estimates), 1.0, 0.0, kicks, (), (threshold,),
                                        np.array([1.0]), np.array([44.2]), none, none, 9,
                                        ProfileFit(np.zeros(len(fits)), 1.0, (), 9, False,
                                                   False), threshold_search_evaluations=4)

    monkeypatch.setattr(joint_fit, 'fit_jointly', known_answer)
    out = tmp_path / 'study.md'
    status = cli.main(['synthetic', 'study', '--protocol', '--device', 'paper_b', '--workers',
                       '1', '--max-evaluations', '9', '--out', str(out)])
    printed = capsys.readouterr().out.strip().splitlines()
    assert status == 0
    assert asked == [(list(device.fit), 9)]
    assert printed[-1] == 'determined 1 of 3; coverage 0.67'
    assert ('4 evaluations of the thresholds alone and 9 of the thresholds and kicks together'
            in printed[0])
    assert any(line.strip().startswith(f'{device.fit[2]}:') and 'OUTSIDE' in line
               for line in printed)
    assert out.read_text().strip().splitlines()[-1] == 'determined 1 of 3; coverage 0.67'
    assert not list(tmp_path.glob('*.partial.jsonl'))
