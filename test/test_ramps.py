"""The slow ramp's jump, as the model reports it (sphere_sim.fitting.ramps)."""

import numpy as np
import pytest

from sphere_sim.fitting.protocol import RAMP_JUMP_RAD as JUMP_RAD
from sphere_sim.fitting.ramps import JUMP_LAG_S, jump_time_s


def _normals(tilt_rad):
    return np.column_stack([np.sin(tilt_rad), np.zeros_like(tilt_rad), np.cos(tilt_rad)])


def test_a_linear_rise_jumps_where_it_has_moved_the_jump_threshold_within_the_lag():
    t = np.arange(0.0, 0.2, 5e-4)
    rate = 1.0  # rad/s from 0.1 s on: JUMP_RAD within JUMP_LAG_S at 0.1 + JUMP_RAD / rate
    tilt = np.where(t > 0.1, (t - 0.1) * rate, 0.0)
    assert JUMP_RAD / rate < JUMP_LAG_S
    assert jump_time_s(t, _normals(tilt)) == pytest.approx(0.1 + JUMP_RAD / rate, abs=1e-6)


def test_a_slow_drift_is_no_jump_and_the_time_moves_continuously_with_the_step():
    t = np.arange(0.0, 0.2, 5e-4)
    assert jump_time_s(t, _normals(0.5 * JUMP_RAD / JUMP_LAG_S * t)) is None
    times = [jump_time_s(t, _normals(np.where(t > s, 2 * JUMP_RAD * np.minimum(
        (t - s) / 2e-3, 1.0), 0.0))) for s in (0.1, 0.10013, 0.10026)]
    assert np.allclose(np.diff(times), 1.3e-4, atol=1e-6)
