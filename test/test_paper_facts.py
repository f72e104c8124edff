"""The paper's facts on the default (``calibrated``) set. Only Fig. 4's pull-in was a
calibration target; every other fact here is a test of the model, never fitted to it."""

import itertools
import json
import math
from pathlib import Path

import numpy as np
import pytest

from sphere_sim.fitting.calibration import evaluate
from sphere_sim.kicks import holding
from sphere_sim.kicks.characteristics import KickBench, direction_error
from sphere_sim.kicks.design import KickDesign
from sphere_sim.kicks.discrete import normal_from_xy
from sphere_sim.kicks.offset_lookup import OffsetLookup, compensating_beam, side_of_axis
from sphere_sim.model.parameters import load_parameter_set
from sphere_sim.studies.runs import literal_kick

RESULTS = Path(__file__).parents[1] / 'bench' / 'results'
PAPER_KICK_DEG = 0.54  # §4.1, Fig. 5 and 6a
CREEP_LIMIT_DEG_PER_S = 1e-3
# The model's prediction of the ratchet: 100 sub-pull-in pulses at 35 deg (Fig. 1d read for
# pulses) move the normal by this much in all; the paper states no number.
RATCHET_DEG = 0.025
# The bound this project once set on it (Fig. 1d read as no motion at all); it yielded to the
# paper's kick size, which only a bristle about 70 times softer than Mindlin's meets with it.
RATCHET_BOUND_DEG = 1e-4
# A tangential contact stiffness whose elastic zone spans the tips' sweep under the pulses
# (docs/parameters.md: the only band that meets that bound lies around it).
SPANNING_BRISTLE_N_PER_M = 1e3


@pytest.fixture(scope='module')
def optimised():
    data = json.loads((RESULTS / 'kick_optimization.json').read_text())
    return data, KickDesign.load(RESULTS / 'kick_optimization.json')


def test_the_papers_layout_turns_the_sphere_towards_minus_45_deg():
    """§4.1: V1 = V2 = 35 V, V3 = V4 = 80 V is the kick from the hind left (Fig. 5, 6a)."""
    kick = literal_kick(load_parameter_set('calibrated'))
    assert kick.direction_deg == pytest.approx(-45.0, abs=5.0)
    assert kick.rotation_deg > 0.1


def test_the_dry_contact_turns_the_papers_way_only_with_the_layout_swapped(tmp_path):
    """dry_contact's finding: the paper's layout turns it backwards, along the mirror line
    towards +135 deg; its own kick, searched with the low and high beams exchanged, goes
    towards -45 deg (a symmetric design cannot leave that line)."""
    from sphere_twin import cli

    dry = load_parameter_set('dry_contact')
    assert literal_kick(dry).direction_deg == pytest.approx(135.0, abs=5.0)
    out = tmp_path / 'dry.json'
    assert cli.main(['optimize-kick', '--params', 'dry_contact', '--layout', 'swapped',
                     '--popsize', '1', '--maxiter', '1', '--workers', '1',
                     '--output', str(out)]) == 0
    data = json.loads(out.read_text())
    assert (data['design']['low_beams'], data['design']['high_beams']) == ([3, 4], [1, 2])
    assert data['parameter_set'] == 'dry_contact' and data['parameter_digest'] == dry.digest()
    assert data['direction_deg'] == pytest.approx(-45.0, abs=1.0) and data['rotation_deg'] > 0.0


def test_the_optimised_kick_keeps_the_papers_layout_size_and_settling(optimised):
    """§4.1: the GA over the widths and the delay with 35/80 V fixed gives 0.54 deg on the
    diagonal (alpha = beta), settled after about 50 ms."""
    data, design = optimised
    assert (design.low_beams, design.high_beams) == ((1, 2), (3, 4))
    assert (design.low_v, design.high_v) == (35.0, 80.0)
    assert data['rotation_deg'] == pytest.approx(PAPER_KICK_DEG, rel=0.2)
    assert data['direction_deg'] == pytest.approx(-45.0, abs=1.0)
    assert 0.025 <= data['settle_time_s'] <= 0.06


def test_from_a_tilt_the_kick_leaves_the_diagonal_and_an_offset_on_v1_turns_it_back(optimised):
    """Fig. 6b and 8: from alpha = -20 deg (x_sn = 0, y_sn = 0.342) the same inputs leave the
    -45 deg line; an offset on V1 (the upper-right half-space's beam, §4.1) turns the direction
    back, the more the larger (up to the 6.2 V of Fig. 8b)."""
    _, design = optimised
    normal = normal_from_xy(0.0, math.sin(math.radians(20.0)))
    assert side_of_axis(design.direction_rad, *normal[:2]) > 0.0
    assert compensating_beam(design, upper_right=True) == 1
    bench = KickBench(load_parameter_set('calibrated'))
    offsets = (0.0, 2.0, 4.0, 6.2)
    errors = [abs(direction_error(bench.effect(normal, design, 1.0, v, 1), design))
              for v in offsets]
    assert math.degrees(errors[0]) > 3.0
    assert all(later < earlier for earlier, later in itertools.pairwise(errors))


# Fig. 10's width at tilt, the full kick over the level one: the paper says it "slightly decreases"
# and "can even become negative", and states no number; these are the model's predictions, which
# a hardware test can check (docs/parameters.md, "Width against tilt"), pinned so that a change
# of the model shows. Without offsets, the reading Fig. 10's text describes; with the shipped
# voltage offsets of §4.1, the table's kicks. +-10 % relative: the one-at-a-time scans over the
# declared ranges move these ratios by more than that (z_G, k_phi, d_B,phi), a nudge of the
# tilt by 1e-4 deg by less than 1e-5.
WIDTH_AT_TILT = {(20.0, False): 0.69, (35.0, False): 0.48, (20.0, True): 0.50, (35.0, True): 0.79}


@pytest.mark.parametrize(('tilt_deg', 'with_offsets'), list(WIDTH_AT_TILT))
def test_the_kick_narrows_with_tilt_as_the_model_predicts(optimised, tilt_deg, with_offsets):
    """Fig. 10: the rotation width decreases with the initial rotation; by how much the paper
    does not say, and the model predicts a quarter to a half less."""
    _, design = optimised
    offsets = (OffsetLookup.load(RESULTS / 'voltage_offsets.json', design, 'calibrated')
               if with_offsets else None)
    ratio = holding.width_ratio(tilt_deg, load_parameter_set('calibrated'), design, offsets)
    assert ratio < 1.0
    assert ratio == pytest.approx(WIDTH_AT_TILT[tilt_deg, with_offsets], rel=0.1)


def test_the_pull_in_is_above_44_v_with_the_sphere_and_lower_without():
    """Fig. 4 (the calibration's one target) and its note that the beams alone need less."""
    with_sphere, beams_only, on_edge = evaluate(load_parameter_set('calibrated'))
    assert 44.0 < with_sphere < 45.0
    assert beams_only < with_sphere
    assert on_edge


@pytest.mark.parametrize('tilt_deg', [20.0, 35.0])
def test_a_sphere_landed_from_a_kick_stays_put(optimised, tilt_deg):
    """Fig. 1d: caught and kept, measured from the state a kick lands in."""
    _, design = optimised
    rate = holding.landed_creep_rate(tilt_deg, params=load_parameter_set('calibrated'),
                                     design=design)
    assert math.degrees(rate) <= CREEP_LIMIT_DEG_PER_S


def test_sub_pull_in_pulses_walk_the_sphere_by_gross_slip_not_by_bristle_creep(optimised):
    """Pulses of 20 V sweep each tip radially by several nanometres (the lever turns about the
    ground plate's edge), far beyond the elastic zone of a contact (a fifth of a nanometre): the
    tips slide, and the weight's torque biases the slip. A softer bristle whose elastic zone
    spans the sweep walks far less, which tells gross slip from the bristle's own creep."""
    _, design = optimised
    cal = load_parameter_set('calibrated')
    stiff = holding.ratchet_rad(35.0, pulses=10, params=cal, design=design)
    soft = holding.ratchet_rad(35.0, pulses=10, design=design,
                               params=cal.replace(**{'friction.bristle_stiffness_n_per_m': 1e3}))
    assert soft < 0.2 * stiff
    model, x = holding.landed_state(35.0, cal, design)
    assert np.all(model.bristle_limits_m(x) < 1e-9)


def test_a_hundred_sub_pull_in_pulses_walk_the_tilted_sphere_as_the_model_predicts(optimised):
    """Fig. 1d read for pulses: 100 pulses of 10-30 V on all beams at 35 deg (`sphere-twin
    validate`'s ratchet line). The paper applies no pulses to a resting sphere and states no
    number; the model predicts 0.025 deg in all, by gross slip of the tips (docs/parameters.md,
    "The ratchet"), which a hardware test can check. +-10 % relative: a bristle four times
    softer than Mindlin's (1e4 N/m, the declared range's low end) gives 0.019 deg, a nudge of the
    tilt by 1e-4 deg moves it by less than 1e-5 of itself."""
    _, design = optimised
    moved = holding.ratchet_rad(35.0, params=load_parameter_set('calibrated'), design=design)
    assert math.degrees(moved) == pytest.approx(RATCHET_DEG, rel=0.1)


def test_a_contact_soft_enough_to_hold_through_the_pulses_widens_the_kick_past_the_papers(
        optimised):
    """Why the ratchet's bound yielded: the one tangential stiffness that holds the sphere
    through the pulses (the contact 70 times softer than Mindlin's) makes the full kick wider
    than §4.1's 0.54 deg + 20 %, a figure of the paper's own. From Mindlin's stiffness (0.025 deg,
    the test above) down to this one the softer bristle walks less: identifying k_b on a device
    decides between the two (docs/parameters.md, "The ratchet against the bristle's stiffness")."""
    _, design = optimised
    soft = load_parameter_set('calibrated').replace(
        **{'friction.bristle_stiffness_n_per_m': SPANNING_BRISTLE_N_PER_M})
    assert math.degrees(holding.ratchet_rad(35.0, params=soft, design=design)) \
        <= RATCHET_BOUND_DEG
    kick = KickBench(soft).effect(normal_from_xy(0.0, 0.0), design, 1.0)
    assert math.degrees(kick.width_rad) > 1.2 * PAPER_KICK_DEG
    assert math.degrees(direction_error(kick, design)) == pytest.approx(0.0, abs=1.0)
