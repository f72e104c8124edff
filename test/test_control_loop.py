"""Closed loops on a synthetic kick plant: convergence, learning, unreachable references."""

import math

import numpy as np
import pytest

from sphere_control.basic import BasicController, BasicParams
from sphere_control.closed_loop import ConePolicy, LoopSettings, Outcome, run_closed_loop
from sphere_control.extended import ExtendedController, ExtendedParams, prelearn
from sphere_control.kick_plants import AnalyticKickPlant, EightDirectionPlant
from sphere_control.perturbations import Mismatch, PerturbedPlant
from sphere_control.reference import CircleTrajectory, Setpoint, clamp_to_cone
from sphere_sim.kicks.discrete import CONE_HALF_ANGLE_RAD, EIGHT_DIRECTIONS_RAD, normal_from_xy

WIDTH_RAD = math.radians(0.54)  # the paper's full kick
PHI_MIN_RAD = math.radians(0.05)  # the paper's narrow resting band
STARTS_XY = [(0.0, 0.0), (0.2, -0.1), (-0.3, 0.25), (0.05, 0.4)]
TARGET_OFFSETS_XY = [(0.01, 0.02), (-0.015, 0.004)]


def plant(mismatch_deg=0.0, width_scale=1.0, exponent=1.5):
    base = AnalyticKickPlant(WIDTH_RAD, exponent=exponent, softening=0.2)
    return PerturbedPlant(base, Mismatch(math.radians(mismatch_deg), width_scale))


def extended(phi_min_rad=PHI_MIN_RAD):
    return ExtendedController(ExtendedParams(phi_min_rad, WIDTH_RAD))


@pytest.mark.parametrize('start', STARTS_XY)
@pytest.mark.parametrize('offset', TARGET_OFFSETS_XY)
def test_extended_controller_settles_inside_the_resting_band(start, offset):
    phi_min = math.radians(0.05)
    reference = Setpoint((start[0] + offset[0], start[1] + offset[1]))
    h = run_closed_loop(extended(phi_min), plant(), normal_from_xy(*start), reference)
    assert h.outcome is Outcome.SETTLED
    assert h.final_error_rad < phi_min
    distance = math.hypot(*offset)
    assert h.kicks_to_settle <= 3 * distance / WIDTH_RAD + 8  # a few kicks beyond the minimum


@pytest.mark.parametrize('start', STARTS_XY)
def test_basic_controller_settles_when_the_band_exceeds_a_kick(start):
    phi_min = 1.2 * WIDTH_RAD
    reference = Setpoint((start[0] + 0.01, start[1] + 0.02))
    params = BasicParams(phi_min, full_width_rad=WIDTH_RAD)
    h = run_closed_loop(BasicController(params), plant(), normal_from_xy(*start), reference)
    assert h.outcome is Outcome.SETTLED
    assert h.final_error_rad < phi_min
    assert np.all(h.intensities[h.actions >= 0] == 1.0)


def test_basic_controller_with_a_narrow_band_circles_the_reference_and_is_stopped():
    """The paper's Fig. 13a: too small a Phi_min makes the basic controller oscillate; the
    loop stops it as STALLED instead of kicking forever."""
    params = BasicParams(math.radians(0.05), full_width_rad=WIDTH_RAD)
    h = run_closed_loop(BasicController(params), plant(exponent=1.0), normal_from_xy(0, 0),
                        Setpoint((0.01, 0.02)), LoopSettings(max_steps=400, stall_kicks=30))
    assert h.outcome is Outcome.STALLED
    assert h.kicks < 60
    assert np.all(h.errors_rad[-10:] < 2.0 * WIDTH_RAD)


@pytest.mark.parametrize('mismatch_deg', [12.0, 33.0])
def test_learning_shrinks_the_direction_error_under_mismatch(mismatch_deg):
    device = plant(mismatch_deg)
    controller = extended()
    before = controller.direction_errors_rad(device.true_directions_rad)
    assert np.allclose(before, math.radians(mismatch_deg))
    settings = LoopSettings(max_steps=300, kick_period_s=0.06)
    lap = CircleTrajectory(0.05, 1.0 / (settings.max_steps * settings.kick_period_s))
    h = run_closed_loop(controller, device, normal_from_xy(0, 0), lap, settings)
    assert h.outcome is Outcome.COMPLETED
    after = controller.direction_errors_rad(device.true_directions_rad)
    assert np.all(after < 0.15 * before)  # one update at alpha_sigma = 0.9 leaves a tenth
    # and the learned directions pay off: the error along the lap is small
    assert np.mean(h.errors_rad[100:]) < 0.5 * WIDTH_RAD


def test_learning_adapts_the_width_to_a_weaker_device():
    """With kicks half as wide as modelled, the learned widths follow the device."""
    device = plant(width_scale=0.5, exponent=1.0)
    controller = prelearn(extended(), device, normal_from_xy(0, 0), 400, seed=1)
    for net in controller.networks:
        assert net(1.0) == pytest.approx(0.5 * WIDTH_RAD, rel=0.06)
        assert net(0.5) == pytest.approx(0.25 * WIDTH_RAD, rel=0.06)


def test_prelearned_controller_needs_no_more_kicks_under_mismatch():
    device = plant(12.0)
    start, reference = normal_from_xy(0, 0), Setpoint((0.01, 0.02))
    fresh = run_closed_loop(extended(), device, start, reference)
    learned = prelearn(extended(), device, start, 40, seed=0)
    pre = run_closed_loop(learned, device, start, reference)
    assert fresh.outcome is Outcome.SETTLED and pre.outcome is Outcome.SETTLED
    assert pre.kicks_to_settle <= fresh.kicks_to_settle


def test_reference_outside_the_cone_is_refused_without_kicking():
    settings = LoopSettings(cone_policy=ConePolicy.REFUSE)
    h = run_closed_loop(extended(), plant(), normal_from_xy(0, 0), Setpoint((0.9, 0.0)),
                        settings)
    assert h.outcome is Outcome.UNREACHABLE
    assert h.kicks == 0
    assert h.reference_clamped


def test_reference_outside_the_cone_is_clamped_to_its_edge_and_reached():
    start = normal_from_xy(0.62, 0.0)
    h = run_closed_loop(extended(), plant(), start, Setpoint((0.9, 0.3)))
    assert h.reference_clamped
    edge = math.sin(CONE_HALF_ANGLE_RAD)
    assert math.hypot(*h.references[-1][:2]) == pytest.approx(edge)
    assert h.outcome is Outcome.SETTLED
    assert math.hypot(*h.normals[-1][:2]) <= edge + WIDTH_RAD


def test_a_plant_that_cannot_get_closer_stops_the_loop_as_stalled():
    """Kicks that no longer move the sphere (width zero at this tilt): no endless kicking."""
    stuck = AnalyticKickPlant(WIDTH_RAD, softening=1.0)  # width 0 at the cone's edge
    edge = math.sin(CONE_HALF_ANGLE_RAD)
    start = normal_from_xy(edge, 0.0)
    settings = LoopSettings(max_steps=10_000, stall_kicks=25)
    h = run_closed_loop(extended(), stuck, start, Setpoint((edge * 0.99, 0.05)), settings)
    assert h.outcome is Outcome.STALLED
    assert h.kicks <= 26


def test_a_plant_that_refuses_a_kick_ends_the_loop_with_plant_limit():
    class Refusing:
        directions_rad = plant().directions_rad

        def kick(self, normal, action, intensity):
            raise ValueError('outside the table')

    h = run_closed_loop(extended(), Refusing(), normal_from_xy(0, 0), Setpoint((0.01, 0.0)))
    assert h.outcome is Outcome.PLANT_LIMIT
    assert h.kicks == 0


def test_clamp_to_cone_keeps_the_direction():
    xy, clamped = clamp_to_cone((0.6, 0.8))
    assert clamped
    assert math.atan2(xy[1], xy[0]) == pytest.approx(math.atan2(0.8, 0.6))
    assert math.hypot(*xy) == pytest.approx(math.sin(CONE_HALF_ANGLE_RAD))
    inside, was = clamp_to_cone((0.1, 0.1))
    assert not was and np.allclose(inside, (0.1, 0.1))


def test_eight_directions_reach_an_axis_setpoint_in_fewer_kicks():
    base = AnalyticKickPlant(WIDTH_RAD)
    reference = Setpoint((0.05, 0.0))
    four = run_closed_loop(extended(), base, normal_from_xy(0, 0), reference)
    params = ExtendedParams(math.radians(0.05), WIDTH_RAD, EIGHT_DIRECTIONS_RAD)
    eight = run_closed_loop(ExtendedController(params), EightDirectionPlant(base),
                            normal_from_xy(0, 0), reference)
    assert eight.outcome is Outcome.SETTLED and four.outcome is Outcome.SETTLED
    assert eight.kicks_to_settle < four.kicks_to_settle
