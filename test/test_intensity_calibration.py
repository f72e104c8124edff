"""The actuator calibration: u_K through the level-state width curve, least voltage first."""

import math

import numpy as np
import pytest

from sphere_control.command import Command
from sphere_control.controllers import make_controller
from sphere_control.intensity_calibration import IntensityCalibration, calibrated
from sphere_control.kick_plants import AnalyticKickPlant
from sphere_sim.kicks.discrete import LEVEL_NORMAL, KickResult, normal_from_xy
from sphere_sim.model.rotations import angle_between

FULL_WIDTH_RAD = math.radians(0.5)


def level_width(kicks, action, intensity):
    return angle_between(LEVEL_NORMAL, kicks.kick(LEVEL_NORMAL, action, intensity).normal)


def test_a_power_law_actuator_is_made_linear_by_its_closed_form_inverse():
    plant = AnalyticKickPlant(FULL_WIDTH_RAD, exponent=1.7)
    calibration = IntensityCalibration.of(plant)
    kicks = calibration.applied_to(plant)
    for u in (0.0, 0.1, 0.35, 0.6, 0.9, 1.0):
        assert calibration.design_intensity(0, u) == pytest.approx(u ** (1 / 1.7), abs=2e-3)
        assert level_width(kicks, 0, u) == pytest.approx(u * FULL_WIDTH_RAD,
                                                         abs=1e-3 * FULL_WIDTH_RAD)


class DippingPlant:
    """Kicks along +x whose width rises to 0.6 W at u = 0.5, dips to 0.4 W at 0.6, then rises
    to W at 1: the shape of a kick past its pull-in."""

    directions_rad = (0.0, 0.5 * math.pi, math.pi, 1.5 * math.pi)
    knots = ((0.0, 0.0), (0.5, 0.6), (0.6, 0.4), (1.0, 1.0))

    def width_rad(self, u):
        us, gs = zip(*self.knots, strict=True)
        return FULL_WIDTH_RAD * float(np.interp(u, us, gs))

    def kick(self, normal, action, intensity):
        h = self.width_rad(intensity)
        d = self.directions_rad[action]
        return KickResult(normal_from_xy(normal[0] + h * math.cos(d), normal[1] + h * math.sin(d)))


def test_of_several_voltages_giving_a_width_the_least_is_taken():
    plant = DippingPlant()
    calibration = IntensityCalibration.of(plant)
    # 0.5 W is reached at u = 5/12 on the first rise, and again at 0.65 after the dip
    assert calibration.design_intensity(0, 0.5) == pytest.approx(0.5 * 0.5 / 0.6, abs=1e-3)
    # above the first peak only the last rise reaches it
    assert calibration.design_intensity(0, 0.8) == pytest.approx(0.6 + 0.4 * 0.4 / 0.6,
                                                                 abs=1e-3)
    # monotone in the calibrated intensity, from no kick to the full one
    u = np.linspace(0.0, 1.0, 101)
    design = [calibration.design_intensity(0, x) for x in u]
    assert design[0] == 0.0 and design[-1] == 1.0
    assert np.all(np.diff(design) >= 0.0)
    kicks = calibration.applied_to(plant)
    widths = [level_width(kicks, 0, x) for x in u]
    assert np.allclose(widths, u * FULL_WIDTH_RAD, atol=2e-3 * FULL_WIDTH_RAD)


def test_a_calibration_refuses_a_plant_of_other_actions():
    calibration = IntensityCalibration.of(DippingPlant())
    with pytest.raises(ValueError, match='4 actions'):
        calibration.applied_to(AnalyticKickPlant(FULL_WIDTH_RAD, directions_rad=(0.0, 1.0)))


@pytest.fixture(scope='module')
def table():
    from sphere_sim.kicks.lookup_table import DEFAULT_TABLE_PATH, LookupTable

    return LookupTable.load_current(DEFAULT_TABLE_PATH)


def test_the_shipped_table_kicks_in_proportion_to_the_calibrated_intensity(table):
    """The design's own intensity moves nothing below about 0.5 and jumps at the pull-in; the
    calibrated one gives u W from the level state for every action."""
    assert level_width(table, 0, 0.45) < 0.01 * level_width(table, 0, 1.0)
    kicks = calibrated(table)
    full = level_width(kicks, 0, 1.0)
    assert full == pytest.approx(level_width(table, 0, 1.0))
    for action in range(4):
        assert kicks.calibration.design_intensity(action, 0.0) == 0.0
        for u in (0.2, 0.5, 0.8):
            assert level_width(kicks, action, u) == pytest.approx(u * full, rel=0.02)


def test_the_programme_is_the_tables_at_the_design_intensity(table):
    kicks = calibrated(table)
    normal = normal_from_xy(0.1, -0.05)
    design = kicks.calibration.design_intensity(2, 0.5)
    assert 0.5 < design < 1.0
    sent = kicks.programme(2, 0.5, normal)
    expected = table.programme(2, design, normal)
    assert all(np.array_equal(a, b) for a, b in zip(sent.segments(), expected.segments(),
                                                    strict=True))


def test_learning_from_every_kick_skips_a_kick_that_did_not_move():
    """A direction needs a displacement: with no threshold (the paper's every kick) a kick
    that left the sphere where it was teaches the width, not sigma."""
    controller = make_controller('extended', math.radians(0.05), FULL_WIDTH_RAD,
                                 (0.25 * math.pi, 0.75 * math.pi, -0.75 * math.pi,
                                  -0.25 * math.pi), direction_learning_min_rad=0.0)
    before = controller.directions_rad.copy()
    controller.observe(LEVEL_NORMAL, Command(1, 0.3), LEVEL_NORMAL)
    assert np.array_equal(controller.directions_rad, before)
    assert controller.networks[1](0.3) < 0.3 * FULL_WIDTH_RAD  # the width was learned
    moved = normal_from_xy(1e-6, 0.0)  # the tiniest kick teaches sigma
    controller.observe(LEVEL_NORMAL, Command(1, 0.3), moved)
    assert controller.directions_rad[1] == pytest.approx(0.1 * 0.75 * math.pi, abs=1e-9)


def test_a_width_above_a_dip_is_asked_where_the_curve_climbs_out_of_it():
    """Sampled every 0.1: the width falls from 0.5 W at u = 0.4 to 0.1 W at 0.5 and reaches
    0.9 W at 0.6. 0.6 W lies on that last climb (u = 0.5 + 0.1 * 5/8), not on a line from the
    old maximum's u = 0.4."""
    class Plant(DippingPlant):
        knots = ((0.0, 0.0), (0.4, 0.5), (0.5, 0.1), (0.6, 0.9), (1.0, 1.0))

    calibration = IntensityCalibration.of(Plant())
    assert calibration.design_intensity(0, 0.6) == pytest.approx(0.5625, abs=1e-3)
    assert calibration.design_intensity(0, 0.45) == pytest.approx(0.36, abs=1e-3)
