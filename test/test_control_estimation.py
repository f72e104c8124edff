"""Perturbed plants, the noisy sensor and the Kalman filter on the surface normal."""

import math

import numpy as np
import pytest

from sphere_control.estimator import KalmanParams, NormalKalmanFilter
from sphere_control.kick_plants import AnalyticKickPlant, EightDirectionPlant
from sphere_control.perturbations import Mismatch, NoisySensor, PerturbedPlant
from sphere_sim.kicks.discrete import EIGHT_DIRECTIONS_RAD, normal_from_xy

WIDTH_RAD = 0.01


def test_perturbed_plant_turns_and_scales_each_kick():
    base = AnalyticKickPlant(WIDTH_RAD)
    device = PerturbedPlant(base, Mismatch(math.radians(33.0), 0.7))
    start = normal_from_xy(0.1, -0.2)
    for action, nominal in enumerate(base.directions_rad):
        moved = device.kick(start, action, 1.0).normal[:2] - start[:2]
        assert math.hypot(*moved) == pytest.approx(0.7 * WIDTH_RAD)
        assert math.atan2(moved[1], moved[0]) == pytest.approx(
            math.remainder(nominal + math.radians(33.0), 2 * math.pi))
    assert device.directions_rad == base.directions_rad


def test_eight_direction_plant_kicks_along_all_eight_directions():
    plant = EightDirectionPlant(AnalyticKickPlant(WIDTH_RAD))
    start = normal_from_xy(0.05, 0.03)
    for action, direction in enumerate(EIGHT_DIRECTIONS_RAD):
        moved = plant.kick(start, action, 1.0).normal[:2] - start[:2]
        assert math.hypot(*moved) == pytest.approx(WIDTH_RAD)
        assert math.atan2(moved[1], moved[0]) == pytest.approx(direction)


def test_noisy_sensor_is_seeded_and_has_the_stated_spread():
    truth = normal_from_xy(0.1, 0.2)
    a = np.array([NoisySensor(1e-3, 5).measure(truth) for _ in range(3)])
    sensor = NoisySensor(1e-3, 5)
    b = sensor.measure(truth)
    np.testing.assert_array_equal(a[0], b)
    samples = np.array([sensor.measure(truth) for _ in range(4000)])
    assert np.allclose(np.linalg.norm(samples, axis=1), 1.0)
    assert np.std(samples[:, 0] - truth[0]) == pytest.approx(1e-3, rel=0.05)
    assert abs(np.mean(samples[:, 1] - truth[1])) < 1e-4


def test_kalman_filter_beats_raw_measurements_along_a_kicked_path():
    """Known kicks with 20 % model error and noisy measurements: the estimate is closer to
    the truth than the measurement, on average by well over a factor of two in variance."""
    rng = np.random.default_rng(0)
    noise = 2e-3
    sensor = NoisySensor(noise, seed=1)
    truth = normal_from_xy(0.0, 0.0)
    kf = NormalKalmanFilter(KalmanParams(noise, 1e-4, kick_relative_std=0.2), truth)
    raw_err, kf_err = [], []
    for _ in range(400):
        planned = 1e-3 * np.array([math.cos(a := rng.uniform(0, 2 * math.pi)), math.sin(a)])
        actual = planned * rng.uniform(0.8, 1.2)
        truth = normal_from_xy(*(truth[:2] + actual))
        kf.predict(planned)
        measured = sensor.measure(truth)
        estimate = kf.update(measured)
        raw_err.append(np.sum((measured[:2] - truth[:2]) ** 2))
        kf_err.append(np.sum((estimate[:2] - truth[:2]) ** 2))
    assert np.mean(kf_err[50:]) < 0.4 * np.mean(raw_err[50:])


def test_kalman_filter_averages_while_resting():
    noise = 1e-3
    truth = normal_from_xy(0.1, 0.0)
    kf = NormalKalmanFilter(KalmanParams(noise, 1e-4, initial_std_rad=1.0), normal_from_xy(0, 0))
    sensor = NoisySensor(noise, seed=2)
    for _ in range(100):
        kf.update(sensor.measure(truth))
    assert np.linalg.norm(kf.xy - truth[:2]) < 3 * noise / math.sqrt(100)
    assert kf.covariance[0, 0] == pytest.approx(noise ** 2 / 100, rel=0.02)
