"""The placeholder plant: holds the resting normal, advances time, validates its inputs."""

import math

import numpy as np
import pytest

from sphere_sim.plants import RestingPlant


def test_resting_plant_keeps_the_normal_up_and_counts_time():
    plant = RestingPlant()
    for _ in range(4):
        normal = plant.step(0.02, np.array([80.0, 0.0, -80.0, 10.0]))
        np.testing.assert_array_equal(normal, [0.0, 0.0, 1.0])
    assert plant.time_s == pytest.approx(0.08)
    # The caller owns the returned array; changing it must not change the plant.
    normal[2] = -1.0
    np.testing.assert_array_equal(plant.step(0.02, np.zeros(4)), [0.0, 0.0, 1.0])


@pytest.mark.parametrize(('dt_s', 'voltages_v', 'reason'), [
    (0.0, np.zeros(4), 'dt_s'),
    (-0.01, np.zeros(4), 'dt_s'),
    (math.nan, np.zeros(4), 'dt_s'),
    (0.01, np.zeros(3), 'voltages_v'),
    (0.01, [0.0, 0.0, math.inf, 0.0], 'voltages_v'),
])
def test_resting_plant_rejects_bad_steps(dt_s, voltages_v, reason):
    plant = RestingPlant()
    with pytest.raises(ValueError, match=reason):
        plant.step(dt_s, voltages_v)
    assert plant.time_s == 0.0
