"""The §5 studies on an analytic plant with the paper's kick: the paper's findings hold."""

import math

import pytest

from sphere_control.closed_loop import Outcome
from sphere_control.controllers import ControllerKind
from sphere_control.evaluation import (
    PAPER_PHI_MIN_RAD,
    PAPER_SETPOINT_NORMAL,
    EvaluationConfig,
    PlantUnderTest,
    oscillates,
    scaled_trajectory,
    setpoint_study,
    tracking_study,
)
from sphere_control.kick_plants import AnalyticKickPlant
from sphere_control.perturbations import Mismatch, PerturbedPlant
from sphere_sim.kicks.discrete import PAPER_FULL_KICK_RAD


@pytest.fixture(scope='module')
def put():
    return PlantUnderTest.measure('analytic', AnalyticKickPlant(PAPER_FULL_KICK_RAD,
                                                                exponent=1.7, softening=0.1))


def test_measured_full_kick_and_scale(put):
    # the plant moves the x-y point by 0.54 deg; the rotation angle is a little larger
    assert math.degrees(put.full_width_rad) == pytest.approx(0.54, rel=1e-4)
    assert put.kick_scale == pytest.approx(1.0, rel=1e-4)
    assert scaled_trajectory(put).frequency_hz == pytest.approx(0.02, rel=1e-4)


@pytest.mark.parametrize('mismatch_deg', [0.0, 12.0])
def test_fig13_14_small_band_basic_oscillates_extended_settle(put, mismatch_deg):
    plant = PerturbedPlant(put.plant, Mismatch(math.radians(mismatch_deg)))
    runs = setpoint_study(put, plant, PAPER_SETPOINT_NORMAL, PAPER_PHI_MIN_RAD[0],
                          EvaluationConfig())
    basic = runs[ControllerKind.BASIC]
    assert basic.outcome is not Outcome.SETTLED
    assert oscillates(basic, put.full_width_rad)
    for kind in (ControllerKind.EXTENDED, ControllerKind.PRELEARNED):
        h = runs[kind]
        assert h.outcome is Outcome.SETTLED
        assert h.final_error_rad < PAPER_PHI_MIN_RAD[0]
        assert h.kicks_to_settle <= 12
    assert (runs[ControllerKind.PRELEARNED].kicks_to_settle
            <= runs[ControllerKind.EXTENDED].kicks_to_settle)


def test_fig13_wide_band_all_settle_with_larger_errors(put):
    runs = setpoint_study(put, put.plant, PAPER_SETPOINT_NORMAL, PAPER_PHI_MIN_RAD[1],
                          EvaluationConfig())
    for h in runs.values():
        assert h.outcome is Outcome.SETTLED
        assert not oscillates(h, put.full_width_rad)
        assert math.radians(0.05) < h.final_error_rad < PAPER_PHI_MIN_RAD[1]


def test_fig15_extended_tracks_better_than_the_best_basic(put):
    """A short run (a quarter period) at a fast kick rate, where the paper's factor shows."""
    plant = PerturbedPlant(put.plant, Mismatch(math.radians(33.0)))
    config = EvaluationConfig(trajectory_periods=0.25, basic_phi_min_widths=(0.5, 1.0))
    result = tracking_study(put, plant, config, kick_period_s=0.03)
    assert result.basic.outcome is Outcome.COMPLETED
    assert 0 < result.catch_up_step < len(result.basic.actions) // 2
    assert result.ratio < 0.5


def test_reference_preview_removes_the_step_behind_on_an_ideal_plant(put):
    """At the paper's pace (about 60 ms per kick) a controller that aims at the current sample
    is one reference step behind; aiming where the reference will be when the kick has settled
    takes most of that lag away, for both controllers."""
    plant = PerturbedPlant(put.plant, Mismatch(math.radians(33.0)))
    config = EvaluationConfig(trajectory_periods=0.25, basic_phi_min_widths=(0.5, 1.0))
    plain = tracking_study(put, plant, config, kick_period_s=0.06)
    ahead = tracking_study(put, plant, config, kick_period_s=0.06, preview=True)
    assert ahead.mse_extended < 0.7 * plain.mse_extended
    assert ahead.mse_basic < plain.mse_basic
    assert ahead.ratio < plain.ratio


def test_preview_changes_nothing_on_a_setpoint(put):
    from sphere_control.closed_loop import LoopSettings, run_closed_loop
    from sphere_control.controllers import make_controller
    from sphere_control.reference import Setpoint

    def run(preview):
        controller = make_controller('extended', PAPER_PHI_MIN_RAD[0], put.full_width_rad,
                                     put.plant.directions_rad)
        return run_closed_loop(controller, put.plant, [0.0, 0.0, 1.0],
                               Setpoint.from_normal(PAPER_SETPOINT_NORMAL),
                               LoopSettings(preview=preview))

    plain, ahead = run(False), run(True)
    assert plain.outcome is Outcome.SETTLED
    assert (plain.actions == ahead.actions).all() and (plain.normals == ahead.normals).all()


@pytest.mark.parametrize(('settle_s', 'period_s'), [(0.0448, 0.05), (0.05, 0.05), (0.0501, 0.06),
                                                    (0.0, 0.06), (math.nan, 0.06)])
def test_default_kick_period_is_the_settle_time_rounded_up(settle_s, period_s):
    put = PlantUnderTest('fake', None, math.radians(0.54), settle_s)
    assert put.kick_period_s == pytest.approx(period_s)
    assert EvaluationConfig().for_plant(put).kick_period_s == pytest.approx(period_s)
    assert EvaluationConfig(kick_period_s=0.03).for_plant(put).kick_period_s == 0.03


def test_speed_study_finds_where_a_slow_kick_rate_is_outrun(put):
    """At the paper's pace the 0.54 deg kick follows eq. (64) everywhere; kicking five times
    less often, each kick must cover five times the path, more than a kick reaches."""
    from sphere_control.evaluation import speed_study

    plant = PerturbedPlant(put.plant, Mismatch(math.radians(33.0)))
    paced = speed_study(put, plant, EvaluationConfig(kick_period_s=0.06))
    assert paced['plant']['fraction_outrun'] == 0.0 and paced['plant']['max_ratio'] < 1.0
    slow = speed_study(put, plant, EvaluationConfig(kick_period_s=0.3))
    assert slow['plant']['max_ratio'] == pytest.approx(5.0 * paced['plant']['max_ratio'],
                                                       rel=0.2)
    assert slow['plant']['fraction_outrun'] > 0.5
    low, high = slow['plant']['tilt_deg_outrun']
    assert 0.0 <= low < high <= 27.0  # eq. (64) stays within 26 deg of tilt
