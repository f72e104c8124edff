"""The experiment protocol (sphere_sim.fitting.protocol): the bisection's logic, the refusal of
a step over the voltage limit, and, on the model, that a recorded protocol brackets the model's
own pull-in threshold and tells two devices apart."""

import numpy as np
import pytest
from physics_helpers import ground_contact_threshold_v

from msg_defs.device import VOLTAGE_LIMIT_V
from sphere_sim.fitting.protocol import (
    ACTUATOR_CAPACITANCE,
    DEFAULT_PROTOCOL,
    PROBE_PULSES,
    BeamsOnlyThreshold,
    Bisection,
    Protocol,
    ProtocolVoltageError,
    SlowRamp,
    ThresholdSearch,
    check_protocol,
    on_wire,
    probe_of,
    pulled_in,
    ramp_of,
)


def run_bisection(threshold_v, low=20.0, high=80.0, resolution=0.2):
    search = Bisection(low, high, resolution)
    while (amplitude := search.next_amplitude()) is not None:
        search.observe(amplitude >= threshold_v)
    return search


@pytest.mark.parametrize('threshold_v', [20.3, 44.5, 47.123, 79.5])
def test_the_bisection_brackets_a_known_threshold_within_the_resolution(threshold_v):
    search = run_bisection(threshold_v)
    below, above = search.bracket
    assert below < threshold_v <= above
    assert above - below <= 0.2
    assert len(search.history) <= 9  # log2(60 / 0.2) rounded up


@pytest.mark.parametrize('threshold_v', [44.25, 47.123, 57.3])
def test_the_default_searches_of_one_threshold_end_on_interleaved_grids(threshold_v):
    """The four beams of a symmetric device share one threshold. Undithered, their searches
    would end in one bracket (one quantisation draw counted four times); the default
    protocol's end in four different brackets, each holding the threshold and no wider than
    the resolution, whose common part is narrower than any one of them."""
    singles = [step for step in DEFAULT_PROTOCOL.steps
               if isinstance(step, ThresholdSearch) and len(step.beams) == 1
               and step.width_s == 5e-3]
    assert len(singles) == 4
    brackets = []
    for step in singles:
        search = step.bisection()
        while (amplitude := search.next_amplitude()) is not None:
            search.observe(amplitude >= threshold_v)
        below, above = search.bracket
        assert below < threshold_v <= above and above - below <= step.resolution_v
        brackets.append((below, above))
    assert len({round(low, 9) for low, _ in brackets}) == 4
    common = min(high for _, high in brackets) - max(low for low, _ in brackets)
    assert 0.0 < common < 0.75 * min(high - low for low, high in brackets)


def test_a_threshold_outside_the_bracket_leaves_that_side_unseen():
    assert run_bisection(90.0).bracket[1] is None
    assert run_bisection(10.0).bracket[0] is None


def test_observe_before_asking_is_refused():
    with pytest.raises(ValueError, match='next_amplitude'):
        Bisection(20.0, 80.0, 0.2).observe(True)


def test_a_step_over_the_voltage_limit_is_refused_in_one_line_naming_it():
    too_high = ThresholdSearch((3,), 5e-3, (30.0, 85.0))
    with pytest.raises(ProtocolVoltageError) as error:
        check_protocol(Protocol((ThresholdSearch((1,), 5e-3, (30.0, 70.0)), too_high)))
    message = str(error.value)
    assert '\n' not in message
    assert 'step 2' in message and too_high.label in message
    assert f'{VOLTAGE_LIMIT_V:g} V' in message
    ramp = SlowRamp((2,), 20.0, 30.0, 81.0)
    with pytest.raises(ProtocolVoltageError, match='ramp of beam 2'):
        check_protocol(Protocol((ramp,)))


def test_the_default_protocol_keeps_to_the_limit_and_names_what_it_needs_beyond_the_wire():
    check_protocol(DEFAULT_PROTOCOL)
    needs = DEFAULT_PROTOCOL.not_on_wire()
    assert needs and all(measurement == ACTUATOR_CAPACITANCE for _, measurement in needs)
    assert all(isinstance(step, BeamsOnlyThreshold) for step, _ in needs)
    assert not any(on_wire(step) for step, _ in needs)
    assert "capacitance" in ACTUATOR_CAPACITANCE


def test_probes_and_ramps_are_recognised_from_their_segments():
    probe = ThresholdSearch((3, 4), 1.5e-3, (30.0, 70.0)).probe(47.5)
    found = probe_of(*probe.segments())
    assert found is not None
    assert (found.beams, found.width_s, found.amplitude_v, found.pulses) == (
        (3, 4), 1.5e-3, 47.5, PROBE_PULSES)
    ramp = SlowRamp((2,), 20.0, 30.0, 40.0).programme()
    assert probe_of(*ramp.segments()) is None
    beams, rate = ramp_of(*ramp.segments())
    assert beams == (2,) and rate == pytest.approx(20.0)
    assert ramp_of(*probe.segments()) is None


def test_the_detection_rule_reads_a_pulled_in_train_and_not_the_noise():
    rng = np.random.default_rng(3)
    noise = 9.4e-4

    def resting(tilt_rad, n=60):
        normals = np.column_stack([tilt_rad + noise * rng.standard_normal(n),
                                   noise * rng.standard_normal(n), np.ones(n)])
        return normals / np.linalg.norm(normals, axis=1)[:, None]

    # Measured on the model: ten pulses below pull-in move the normal some 2e-4 rad, ten
    # pulled-in pulses some 2e-3.
    assert not pulled_in(resting(0.0), resting(2e-4))
    assert pulled_in(resting(0.0), resting(2.1e-3))


# --- on the model -------------------------------------------------------------------------------

BEAM = 3
WIDTH_S = 5e-3
BRACKET_V = (36.0, 52.0)
COARSE_V = 1.0


def direct_threshold_v(params, beam=BEAM, width_s=WIDTH_S, resolution_v=0.05):
    """The model's own single-beam threshold from level: a rear end on the ground during one
    pulse, bisected."""
    return ground_contact_threshold_v(params, beam, width_s, *BRACKET_V, resolution_v)


@pytest.fixture(scope='module')
def recorded(tmp_path_factory):
    """One beam, one width, a coarse resolution, on `calibrated` and on paper_b's truth; the
    step that needs the capacitance goes along to be reported."""
    from sphere_sim.model.parameters import load_parameter_set
    from sphere_twin.protocol_bag import read_protocol
    from sphere_twin.protocol_run import record_protocol
    from sphere_twin.synthetic_device import PAPER_DEVICES

    calibrated = load_parameter_set('calibrated')
    paper_b = next(d for d in PAPER_DEVICES if d.name == 'paper_b').truth(calibrated)
    protocol = Protocol((ThresholdSearch((BEAM,), WIDTH_S, BRACKET_V, COARSE_V),
                         BeamsOnlyThreshold((1, 2, 3, 4), WIDTH_S, (20.0, 70.0))))
    out = {}
    for name, params in (('calibrated', calibrated), ('paper_b', paper_b)):
        bag = tmp_path_factory.mktemp('protocol') / name
        record = record_protocol(bag, params, protocol, seed=5)
        out[name] = (params, record, read_protocol(bag))
    return out


@pytest.mark.parametrize('device', ['calibrated', 'paper_b'])
def test_the_recorded_bracket_contains_the_models_own_threshold(recorded, device):
    params, record, results = recorded[device]
    (bracket,) = results.brackets
    assert (bracket.beams, bracket.width_s) == ((BEAM,), WIDTH_S)
    assert bracket.pulled_in_v - bracket.not_pulled_in_v <= COARSE_V
    assert bracket.contains(direct_threshold_v(params))
    # What the recorder decided while running is what the bag says afterwards.
    assert record.brackets[0][1] == (bracket.not_pulled_in_v, bracket.pulled_in_v)


def test_two_devices_whose_pull_in_differs_give_brackets_that_separate(recorded):
    (a,) = recorded['calibrated'][2].brackets
    (b,) = recorded['paper_b'][2].brackets
    assert b.pulled_in_v <= a.not_pulled_in_v  # paper_b's softer beams pull in lower


def test_the_beams_only_step_is_reported_as_needing_the_capacitance(recorded):
    _, record, _ = recorded['calibrated']
    (label, needs), = record.not_run
    assert 'without the sphere' in label and needs == ACTUATOR_CAPACITANCE
