"""Friction must dissipate; the printed reading of Table A1 is kept only as a flagged variant."""

import numpy as np
import pytest
from physics_helpers import scene_with

from sphere_sim import dynamics
from sphere_sim.friction import friction_magnitude
from sphere_sim.initial_state import rest_state
from sphere_sim.model import assemble


def _generalised_friction_power(model, x):
    """Q_friction . qdot computed from the kernel as (friction on) - (friction off) forces."""
    diag = np.empty(dynamics.N_DIAG)
    model.rhs(0.0, x, np.zeros(model.n_beams), diag)
    return diag[dynamics.D_POWER_FRICTION]


@pytest.mark.parametrize('reading', ['dissipative', 'printed'])
def test_friction_power_sign_on_random_contact_states(reading):
    rng = np.random.default_rng(7)
    scene = scene_with()
    params = scene.parameters().replace(**{'friction.reading': reading})
    model = assemble(scene, params)
    x0 = rest_state(assemble(scene))
    o = model.sphere_offset
    powers = []
    for _ in range(400):
        x = x0.copy()
        x[o:o + 3] += rng.normal(0, 2e-9, 3)  # keep the tips in contact
        x[2 * 4:4 * 4] = rng.normal(0, 0.05, 8) * np.tile([1, 100], 4)
        x[o + 7:o + 10] = rng.normal(0, 0.05, 3)
        x[o + 10:o + 13] = rng.normal(0, 50.0, 3)
        powers.append(_generalised_friction_power(model, x))
    powers = np.array(powers)
    assert np.count_nonzero(powers) > 300
    if reading == 'dissipative':
        assert np.all(powers <= 0.0)
    else:
        assert np.any(powers > 0.0)


def test_dissipative_magnitude_is_never_negative_and_has_its_bump_at_v_s():
    v = np.linspace(0, 1.0, 2001)
    f = np.array([friction_magnitude(s, 1e-4, 1.0, 0.05, 2.0, 0.1, 0.5, 0.1, True, True, True,
                                     False) for s in v])
    assert np.all(f >= 0)
    stribeck_only = np.array([friction_magnitude(s, 1.0, 1.0, 0.05, 2.0, 0.1, 0.5, 0.1, False,
                                                 False, True, False) for s in v])
    assert v[np.argmax(stribeck_only)] == pytest.approx(0.1, abs=1e-3)
    assert stribeck_only.max() == pytest.approx(0.5, rel=1e-6)


def test_printed_reading_injects_energy_at_stribeck_velocity():
    # f(v_s) = mu_s F_n with mu_s = +0.5 in the paper's sign convention: a driving force.
    f = friction_magnitude(0.1, 1e-4, 1.0, 0.05, 2.0, 0.1, 0.5, 0.1, True, True, True, True)
    assert f == pytest.approx(-0.5 * 1e-4, rel=1e-9)
