"""Rest equilibrium (§4.1) and the symmetry of the device."""

from functools import lru_cache

import numpy as np
from physics_helpers import pulses, scene_with

from sphere_sim.initial_state import rest_state
from sphere_sim.model import assemble
from sphere_sim.solve import simulate


@lru_cache
def _rest(parameter_set='calibrated'):
    model = assemble(scene_with(parameter_set=parameter_set))
    return model, rest_state(model)


def test_rest_is_an_equilibrium_with_tips_on_the_front_edge():
    model, x = _rest()
    dxdt = model.rhs(0.0, x, np.zeros(4))
    beam_accel = dxdt[8:16]
    sphere_accel = dxdt[model.sphere_offset + 7:]
    # 1e-6 of the weight per tip on a 97 ug beam is ~ 8e-4 m/s^2.
    assert np.max(np.abs(beam_accel[0::2])) < 1e-2
    assert np.max(np.abs(sphere_accel[:3])) < 1e-4
    rear, front = model.ground_gaps(x)
    assert np.all(front < 0) and np.all(rear > 5e-6)  # resting on the front edge, §4.1
    assert np.all(model.sphere_gaps(x) < 0)


def test_sphere_stays_put_for_one_second():
    model, x0 = _rest()
    traj = simulate(model, x0, 1.0, rtol=1e-7, sample_period_s=0.1)
    normal = traj.surface_normal()
    tilt = np.arccos(np.clip(normal[2], -1, 1))
    assert np.max(tilt) < 1e-9
    o = model.sphere_offset
    assert np.max(np.abs(traj.x[o:o + 3] - x0[o:o + 3, None])) < 1e-9


def test_equal_voltages_give_no_rotation():
    model, x0 = _rest()
    traj = simulate(model, x0, 0.02, pulses([50, 50, 50, 50], width_s=0.005), rtol=1e-7,
                    sample_period_s=1e-4)
    o = model.sphere_offset
    assert np.max(traj.x[o + 2] - x0[o + 2]) > 1e-6  # the kick happened
    tilt = np.arccos(np.clip(traj.surface_normal()[2], -1, 1))
    assert np.max(tilt) < 1e-9


def test_mirrored_programme_gives_mirrored_motion():
    # Mirroring at the x-z plane swaps beams 2 and 4 and maps the normal (x, y, z) -> (x, -y, z).
    model, x0 = _rest()
    programme = pulses([35, 35, 80, 80], width_s=0.004)
    mirrored = programme.mirrored({1: 1, 2: 4, 3: 3, 4: 2})
    a = simulate(model, x0, 0.01, programme, rtol=1e-8, sample_period_s=5e-4).surface_normal()
    b = simulate(model, x0, 0.01, mirrored, rtol=1e-8, sample_period_s=5e-4).surface_normal()
    assert np.max(np.abs(a[:2])) > 1e-5  # the sphere did rotate
    np.testing.assert_allclose(b, a * np.array([[1.0], [-1.0], [1.0]]), atol=1e-6 * 1e-2 + 1e-8)
