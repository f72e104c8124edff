"""The reference's motion from its samples, and what the controller node does with it."""

import math

import numpy as np
import pytest

from sphere_control.controllers import make_controller
from sphere_control.kick_cycle import KickCycle
from sphere_control.reference import CircleTrajectory
from sphere_control.reference_motion import ReferenceMotion
from sphere_sim.kicks.discrete import DIAGONAL_DIRECTIONS_RAD, normal_from_xy

RATE_HZ = 10.0  # the reference node's default


def feed(motion, xy_at, t0, t1):
    for t in np.arange(t0, t1, 1.0 / RATE_HZ):
        motion.add(t, normal_from_xy(*xy_at(t)))


def test_a_straight_motion_is_estimated_exactly():
    motion = ReferenceMotion()
    v = np.array([0.01, -0.02])
    feed(motion, lambda t: np.array([0.1, 0.05]) + v * t, 0.0, 1.0)
    np.testing.assert_allclose(motion.velocity_xy(), v, rtol=1e-9)
    assert motion.jumps == 0


def test_eq64_is_followed_without_false_jumps():
    circle = CircleTrajectory(0.44, 0.0272)  # eq. (64) scaled as in the evaluation
    motion = ReferenceMotion()
    feed(motion, circle.xy_at, 0.0, 40.0)
    assert motion.jumps == 0
    t = motion.times_s[-1]
    true_v = (circle.xy_at(t + 1e-4) - circle.xy_at(t - 1e-4)) / 2e-4
    # The line through the last 0.5 s lags the circle's tangent by about a quarter second of
    # its turning (0.34 rad/s): a few percent of the speed.
    assert np.linalg.norm(motion.velocity_xy() - true_v) < 0.1 * np.linalg.norm(true_v)
    # Where the reference will be one kick later: the preview is off by a tenth of the step
    # that aiming at the newest sample would miss by.
    later = circle.xy_at(t + 0.05)
    assert (np.linalg.norm(motion.ahead(0.05)[:2] - later)
            < 0.15 * np.linalg.norm(circle.xy_at(t) - later))


def test_a_jump_restarts_the_estimate_instead_of_extrapolating_it():
    motion = ReferenceMotion()
    feed(motion, lambda t: np.array([0.0, 0.0]), 0.0, 1.0)
    assert not motion.add(1.0, normal_from_xy(0.0, 0.0))
    assert motion.add(1.1, normal_from_xy(0.05, 0.0))  # a new setpoint, 2.9 deg away
    # Right after the jump the reference stands still where it jumped to: no overshoot.
    np.testing.assert_array_equal(motion.velocity_xy(), [0.0, 0.0])
    np.testing.assert_allclose(motion.ahead(0.06)[:2], [0.05, 0.0], atol=1e-15)
    feed(motion, lambda t: np.array([0.05, 0.0]), 1.2, 2.0)
    np.testing.assert_allclose(motion.velocity_xy(), [0.0, 0.0], atol=1e-12)
    assert motion.jumps == 1


def cycle(preview):
    controller = make_controller('basic', math.radians(0.05), math.radians(0.54),
                                 DIAGONAL_DIRECTIONS_RAD)
    return KickCycle(controller, kick_period_s=0.05, preview=preview)


def test_the_cycle_aims_ahead_only_with_preview():
    v = np.array([0.02, 0.0])
    plain, ahead = cycle(False), cycle(True)
    for c in (plain, ahead):
        for t in np.arange(0.0, 1.0, 0.1):
            c.on_reference(normal_from_xy(*(v * t)), t)
    np.testing.assert_array_equal(plain.target(0.95), plain.reference)
    np.testing.assert_allclose(ahead.target(0.95)[:2], v * 0.95, atol=1e-12)


def test_the_preview_runs_from_the_reference_stamp_to_the_landing():
    """The reference arrives at 10 Hz, the normal at 100 Hz: a kick decided 80 ms after the
    newest reference sample lands a kick period later, 130 ms after it. A landing time before
    the sample aims at the sample; one far beyond it (a reference on another clock) is
    capped."""
    v = np.array([0.02, 0.0])
    c = cycle(True)
    for t in np.arange(0.0, 1.0, 0.1):
        c.on_reference(normal_from_xy(*(v * t)), t)
    np.testing.assert_allclose(c.target(0.9 + 0.08 + 0.05)[:2], v * 1.03, atol=1e-12)
    np.testing.assert_allclose(c.target(0.5)[:2], v * 0.9, atol=1e-12)
    cap = 0.05 + c.reference_motion.history_s
    np.testing.assert_allclose(c.target(1e6)[:2], v * (0.9 + cap), atol=1e-12)


@pytest.mark.parametrize(('speed', 'outrun'), [(0.02, False), (0.5, True)])
def test_the_cycle_reports_a_reference_faster_than_its_kicks(speed, outrun):
    c = cycle(False)
    for t in np.arange(0.0, 1.0, 0.1):
        c.on_reference(normal_from_xy(speed * t, 0.0), t)
    # Along +x the basic model's four diagonal kicks reach W cos 45 deg per 50 ms.
    expected = speed * 0.05 / (math.radians(0.54) / math.sqrt(2.0))
    assert c.speed_ratio() == pytest.approx(expected, rel=1e-9)
    assert (c.speed_ratio() > 1.0) is outrun


@pytest.mark.parametrize('time_s', [0.0, 3.3, 12.5, 31.0])
def test_the_trajectory_velocity_is_the_derivative_of_its_points(time_s):
    trajectory = CircleTrajectory()
    h = 1e-5
    numeric = (trajectory.xy_at(time_s + h) - trajectory.xy_at(time_s - h)) / (2 * h)
    np.testing.assert_allclose(trajectory.velocity_xy(time_s), numeric, atol=1e-9)


def test_the_offline_preview_follows_the_motion_and_does_not_foresee_a_switch():
    """As the node's estimate, the offline preview extrapolates the motion at the decision:
    a setpoint about to give way to the trajectory is aimed at as it is."""
    from sphere_control.reference import ScheduledReference, Setpoint, preview

    schedule = ScheduledReference(Setpoint((0.01, 0.02)), CircleTrajectory(), switch_s=3.0,
                                  offset_s=12.5)
    before = preview(schedule, 2.98, 0.04)
    np.testing.assert_allclose(before.normal[:2], [0.01, 0.02], atol=1e-15)
    during = preview(schedule, 3.2, 0.04)
    exact = schedule.xy_at(3.24)
    assert np.hypot(*(during.normal[:2] - exact)) < 1.2e-5  # half the acceleration T^2
    assert np.hypot(*(schedule.xy_at(3.2) - exact)) > 1e-3
