"""System identification: fitting the twin to a device's recordings (docs/identification.md).

The physics test records a synthetic device (the continuous twin with two parameters changed,
sensor noise of the noise study) and identifies it from the bag alone; the others check the
parts on data whose answer is known by construction.
"""

import math

import numpy as np
import pytest
import yaml

from sphere_sim.kicks import identification as idf
from sphere_sim.model.parameters import load_parameter_set

BASE = load_parameter_set('calibrated')
SIGMA = 1e-3


def _stretch(rng, normal, n):
    """``n`` samples of a resting ``normal`` with tangential noise SIGMA per axis."""
    t1 = np.cross(normal, [1.0, 0.0, 0.0])
    t1 /= np.linalg.norm(t1)
    t2 = np.cross(normal, t1)
    e = rng.normal(0.0, SIGMA, (n, 2))
    out = normal + e[:, :1] * t1 + e[:, 1:] * t2
    return out / np.linalg.norm(out, axis=1)[:, None]


def _recording(rest_normals, period_s=0.02, per_stretch=40, window_s=0.06, seed=0):
    """Samples resting at each normal in turn, a programme between consecutive stretches
    (the samples inside its window moving), as a device would record them."""
    rng = np.random.default_rng(seed)
    t, normals, programmes, now = [], [], [], 0.0
    times, volts = np.array([0.0, 2e-3]), np.array([[80.0, 80.0, 35.0, 35.0], [0.0] * 4])
    for i, normal in enumerate(rest_normals):
        if i:
            programmes.append((now, times, volts))
            for _ in range(round(window_s / period_s)):  # the transient: far off, unused
                t.append(now)
                normals.append(np.array([0.1, 0.1, 0.99]) / np.linalg.norm([0.1, 0.1, 0.99]))
                now += period_s
        for sample in _stretch(rng, np.asarray(normal, dtype=float), per_stretch):
            t.append(now)
            normals.append(sample)
            now += period_s
    return np.array(t), np.array(normals), programmes


def _unit(x, y):
    return np.array([x, y, math.sqrt(1.0 - x * x - y * y)])


def test_observations_average_each_resting_stretch_and_measure_the_sensor_noise():
    rests = [_unit(0.01 * i, -0.005 * i) for i in range(12)]
    t, normals, programmes = _recording(rests)
    obs = idf.observations_from_samples(t, normals, programmes)
    assert len(obs.kicks) == 11 and obs.dropped == 0
    for k, kick in enumerate(obs.kicks):
        assert kick.samples_before == kick.samples_after == 40
        # The mean of 40 samples is good to SIGMA / sqrt(40) per axis; 4 of those allowed.
        assert np.linalg.norm(kick.normal_before - rests[k]) < 4 * SIGMA / math.sqrt(40) * 1.5
        assert np.linalg.norm(kick.normal_after - rests[k + 1]) < 4 * SIGMA / math.sqrt(40) * 1.5
    # 12 stretches of 40 two-axis samples: the estimate is good to about 3 %.
    assert obs.noise_std_rad == pytest.approx(SIGMA, rel=0.1)
    expected = SIGMA * math.sqrt(2 / 40)
    assert obs.residual_std_rad() == pytest.approx(np.full(22, obs.noise_std_rad / SIGMA
                                                           * expected))


def test_a_powered_hold_or_a_recording_without_pauses_leaves_kicks_out():
    rests = [_unit(0.0, 0.0), _unit(0.01, 0.0), _unit(0.02, 0.0)]
    t, normals, programmes = _recording(rests)
    held = idf.observations_from_samples(t, normals, programmes,
                                         holds=[(programmes[1][0] + 0.3, [10.0, 0, 0, 0])])
    # The hold lies in the stretch after the second kick: that kick and the first one's
    # "after" are unaffected, the second is dropped.
    assert len(held.kicks) == 1 and held.dropped == 1
    t, normals, programmes = _recording(rests, per_stretch=1)
    with pytest.raises(idf.IdentificationError, match='pauses between programmes'):
        idf.observations_from_samples(t, normals, programmes)


def test_fitted_parameters_are_the_declared_ones_or_those_named():
    declared = idf.fit_parameters(BASE)
    assert [f.path for f in declared] == [u.path for u in BASE.uncertain]
    coulomb = next(f for f in declared if f.path == 'friction.coulomb')
    assert coulomb.tied == ('friction.stribeck',) and coulomb.declared
    # A tied path names its leader; an undeclared path gets the search bound, negative too.
    named = idf.fit_parameters(BASE, ['friction.stribeck', 'beam.ground_z_m'])
    assert [f.path for f in named] == ['friction.coulomb', 'beam.ground_z_m']
    ground = named[1]
    assert not ground.declared
    assert (ground.low, ground.high) == pytest.approx((BASE.beam.ground_z_m * 2,
                                                       BASE.beam.ground_z_m / 2))
    for fit in (*declared, ground):
        for value in (fit.low, fit.high, 0.5 * (fit.low + fit.high)):
            assert fit.from_unit(fit.to_unit(value)) == pytest.approx(value, rel=1e-12)
    p = idf.params_at(BASE, named, [0.4, -12e-6])
    assert (p.friction.coulomb, p.friction.stribeck, p.beam.ground_z_m) == (0.4, 0.4, -12e-6)
    with pytest.raises(idf.IdentificationError, match='unknown parameter'):
        idf.fit_parameters(BASE, ['beam.wingspan_m'])
    with pytest.raises(idf.IdentificationError, match='not a number'):
        idf.fit_parameters(BASE, ['friction.reading'])


def test_selection_holds_a_parameter_the_kicks_cannot_tell_from_another():
    rng = np.random.default_rng(3)
    a, b = rng.normal(0, 50, 40), rng.normal(0, 50, 40)
    jac = np.column_stack([a, b, -0.7 * a + rng.normal(0, 0.5, 40), rng.normal(0, 0.1, 40)])
    selected, held = idf.select_identifiable(jac, np.ones(40))
    assert sorted(selected) == [0, 1]
    status, partner, cos = held[2]
    assert status == 'entangled' and partner == 0 and cos < -0.99
    assert held[3][0] == 'unresolved'
    # Alone, the entangled one is perfectly identifiable: it is the pair that is not.
    assert idf.select_identifiable(jac[:, [2]], np.ones(40)) == ([0], {})


def _kick_observations(params, n, seed=0, noise=0.0):
    """Noiseless (or noisy) kick observations of the continuous model itself."""
    from sphere_sim.kicks.discrete import normal_from_xy
    from sphere_sim.twin.plant_setup import load_kick_model

    rng = np.random.default_rng(seed)
    kicks = load_kick_model()
    out = []
    for i in range(n):
        before = normal_from_xy(*rng.uniform(-0.03, 0.03, 2))
        times, volts = kicks.programme(i % 4, float(rng.uniform(0.6, 1.0))).segments()
        probe = idf.KickObservation(float(i), times, volts, before, before, 40, 40)
        after = idf.kick_end_normal(params, probe)
        out.append(idf.KickObservation(float(i), times, volts, before, after, 40, 40))
    return idf.Observations(tuple(out), noise)


class StopFitError(Exception):
    pass


def test_an_interrupted_identification_resumes_from_its_checkpoint(tmp_path):
    truth = BASE.replace(**{'beam.damping_phi_nms_per_rad': 6e-9})
    obs = _kick_observations(truth, 5, noise=1e-4)
    fits = idf.fit_parameters(BASE, ['beam.damping_phi_nms_per_rad'])
    whole = idf.identify(BASE, obs, fits)
    checkpoint = tmp_path / 'fit.partial.jsonl'

    def stop_after_three(ev):
        if len(ev.cache) >= 3:
            raise StopFitError

    with pytest.raises(StopFitError):
        idf.identify(BASE, obs, fits, checkpoint=checkpoint, progress=stop_after_three)
    resumed = idf.identify(BASE, obs, fits, checkpoint=checkpoint)
    assert resumed.resumed_evaluations >= 3
    assert resumed.simulated_kicks == whole.simulated_kicks - 5 * resumed.resumed_evaluations
    assert resumed.values() == whole.values()
    # Noiseless kicks of the model itself: the fit lands on the truth, well inside 2 s.e.
    fitted = whole.parameters[0]
    assert fitted.status == 'fitted'
    assert abs(fitted.value - 6e-9) < max(fitted.uncertainty, 0.01 * 6e-9)
    # A checkpoint of another problem is not read back.
    other = idf.identify(BASE, obs, idf.fit_parameters(BASE, ['beam.stiffness_z_n_per_m']),
                         checkpoint=checkpoint)
    assert other.resumed_evaluations == 0


@pytest.fixture(scope='module')
def device_bag(tmp_path_factory):
    """A synthetic device: friction and the beams' damping changed, 14 kicks with the noise
    study's sensor noise."""
    from sphere_twin.commands.synthetic import _device, record

    bag = tmp_path_factory.mktemp('device') / 'device_a'
    record(_device('device_a'), bag, 14)
    return bag


def test_a_synthetic_device_is_identified_from_its_bag(device_bag, tmp_path, monkeypatch,
                                                       capsys):
    """Changed parameters come back within their reported uncertainty and the unchanged one
    stays put; only the device's topics are read; the fitted file loads and holds the values.
    """
    import sphere_twin.run_analysis as run_analysis
    from sphere_twin import cli

    topics_read = set()
    original = run_analysis.read_messages

    def spy(bag_dir, topics=None):
        topics_read.update(topics or ['everything'])
        return original(bag_dir, topics)

    monkeypatch.setattr(run_analysis, 'read_messages', spy)
    out = tmp_path / 'fitted.yaml'
    status = cli.main(['identify', str(device_bag), '--fit', 'friction.coulomb',
                       'beam.damping_phi_nms_per_rad', 'beam.stiffness_phi_nm_per_rad',
                       '--out', str(out)])
    lines = capsys.readouterr().out.strip().splitlines()
    assert status == 0
    assert topics_read <= {'/beams/pulse_program', '/beams/voltage_command',
                           '/sphere/surface_normal', '/sphere/reference'}
    truth = load_parameter_set(str(device_bag / 'truth.yaml'))
    fitted = load_parameter_set(str(out))
    report = yaml.safe_load(out.read_text())['identification']
    by_path = {p['path']: p for p in report['parameters']}
    for path in ('friction.coulomb', 'beam.damping_phi_nms_per_rad',
                 'beam.stiffness_phi_nm_per_rad'):
        p = by_path[path]
        assert fitted.get(path) == p['value']
        if p['status'] == 'fitted':
            assert abs(p['value'] - truth.get(path)) <= p['uncertainty'], p
            # The uncertainty says something: under the declared range's width.
            assert p['uncertainty'] < 0.5 * (p['range'][1] - p['range'][0]), p
        else:
            assert p['value'] == BASE.get(path)
    assert fitted.friction.stribeck == fitted.friction.coulomb
    # Unchanged on this device: it stays within its uncertainty of where it started.
    kphi = by_path['beam.stiffness_phi_nm_per_rad']
    assert abs(kphi['value'] - kphi['start']) <= (kphi['uncertainty'] or 0.0)
    assert kphi['start'] == truth.beam.stiffness_phi_nm_per_rad
    assert len(report['per_kick']) == 14
    rms = report['residual_rms_rad']
    assert rms['fitted'] <= rms['start']
    assert out.with_suffix('.png').stat().st_size > 10_000
    assert not out.with_suffix('.partial.jsonl').exists()
    k = sum(1 for p in report['parameters'] if (
        abs(p['value'] - truth.get(p['path'])) <= p['uncertainty'] if p['status'] == 'fitted'
        else p['value'] == truth.get(p['path'])))
    assert lines[-1] == (f'identified: {k} of 3 parameters within their uncertainty of the '
                         'truth')


@pytest.mark.parametrize('argv, message', [
    (['--fit', 'beam.wingspan_m'], "unknown parameter 'beam.wingspan_m'"),
    (['--fit', 'friction.reading'], 'not a number'),
])
def test_a_bad_request_is_one_line(device_bag, tmp_path, capsys, argv, message):
    from sphere_twin import cli

    status = cli.main(['identify', str(device_bag), '--out', str(tmp_path / 'x.yaml'), *argv])
    err = capsys.readouterr().err.strip().splitlines()
    assert status == 2 and len(err) == 1
    assert err[0].startswith('sphere-twin identify: error: ') and message in err[0]
    assert not (tmp_path / 'x.yaml').exists()


def test_replay_check_shows_the_error_before_and_after(device_bag, tmp_path, capsys):
    """The device's own parameters replay its recording better than the shipped set."""
    import json

    from sphere_twin import cli

    status = cli.main(['replay-check', str(device_bag), '--params',
                       str(device_bag / 'truth.yaml'), '--out', str(tmp_path)])
    lines = capsys.readouterr().out.strip().splitlines()
    assert status == 0
    data = json.loads((tmp_path / f'{device_bag.name}_replay.json').read_text())
    assert data['plant'] == 'continuous' and data['before']['params'] == 'calibrated'
    assert data['rms_error_rad'] < data['before']['rms_error_rad']
    assert lines[-3].startswith('replay error before (calibrated)')
    assert lines[-2].startswith('replay error after (device_a_truth)')
    assert lines[-1].startswith('improvement: RMS')


def test_a_start_set_given_as_a_file_is_kept_beside_the_fitted_one(tmp_path):
    from sphere_twin.commands.identify import write_fitted

    start_file = tmp_path / 'stiffer.yaml'
    start_file.write_text('base: calibrated\nname: stiffer\n'
                          'overrides:\n  beam.stiffness_z_n_per_m: 40.0\n')
    start = load_parameter_set(str(start_file))
    fits = idf.fit_parameters(start, ['friction.coulomb'])
    fitted_p = idf.FittedParameter('friction.coulomb', 0.3, 0.35, 0.05, 0.1, 0.8, True,
                                   'fitted', '', ('friction.stribeck',))
    result = idf.IdentificationResult([fitted_p], np.zeros((3, 2)), np.zeros((3, 2)), 1e-3,
                                      np.ones((1, 1)), 4, 12, 0, 'done', 1.0)
    obs = idf.Observations(tuple(idf.KickObservation(float(i), np.zeros(1), np.zeros((1, 4)),
                                                     np.array([0, 0, 1.0]),
                                                     np.array([0, 0, 1.0]), 5, 5)
                                 for i in range(3)), 1e-3)
    assert fits[0].tied == fitted_p.tied
    out = write_fitted(tmp_path / 'fit.yaml',
                       start, result, obs, [str(tmp_path / 'bag')], 1.0)
    loaded = load_parameter_set(str(out))
    assert loaded.beam.stiffness_z_n_per_m == 40.0  # the start set, through its copy
    assert (loaded.friction.coulomb, loaded.friction.stribeck) == (0.35, 0.35)
    assert (tmp_path / 'fit_start.yaml').exists()


class _Analytic:
    """An evaluator of residuals given as a function of the scaled parameters."""

    def __init__(self, fun):
        self.fun = fun

    def __call__(self, u):
        return self.fun(np.asarray(u, dtype=float))

    def many(self, points):
        return [self(p) for p in points]


def test_the_curvature_is_checked_over_the_interval_it_reports():
    rng = np.random.default_rng(0)
    a = rng.normal(0.0, 1.0, 30)
    noise = np.full(30, 0.1)
    u0 = np.array([0.5])
    for shape, widened in ((lambda x: x, False), (lambda x: 0.02 * np.tanh(x / 0.02), True)):
        ev = _Analytic(lambda u, shape=shape: a * shape(u[0] - u0[0]))
        jac = (ev(u0 + 1e-4) - ev(u0))[:, None] / 1e-4
        cov = idf.covariance(jac, noise)
        checked = idf._secant_checked(ev, u0, [0], cov, noise)
        if not widened:  # a linear residual: the quadratic model is exact
            assert checked == pytest.approx(cov, rel=1e-6)
            continue
        # tanh saturates: two standard errors out, the sum of squares rises less than the
        # quadratic model says, and the variance grows by that ratio.
        step = 2.0 * math.sqrt(cov[0, 0])
        rise = np.sum((ev(u0 + step) / noise) ** 2)
        assert rise < 4.0
        assert checked[0, 0] == pytest.approx(cov[0, 0] * 4.0 / rise, rel=1e-6)
