"""The D4 symmetry of the device: group structure and simulated images of a kick (Fig. 7)."""

import math

import numpy as np
import pytest
from physics_helpers import scene_with

from sphere_sim.integrate.solve import simulate
from sphere_sim.model.assembly import assemble
from sphere_sim.model.initial_state import rest_state
from sphere_sim.model.symmetry import KICK_AXIS_MIRROR, Symmetry, all_symmetries
from sphere_sim.studies.validation import all_beams


def test_beam_maps_are_permutations_matching_the_paper_layout():
    assert Symmetry(1).beam_map() == {1: 4, 2: 1, 3: 2, 4: 3}  # a quarter turn counter-clockwise
    assert Symmetry(0, True).beam_map() == {1: 1, 2: 4, 3: 3, 4: 2}
    assert KICK_AXIS_MIRROR.beam_map() == {1: 2, 2: 1, 3: 4, 4: 3}
    for g in all_symmetries():
        assert sorted(g.beam_map().values()) == [1, 2, 3, 4]
        np.testing.assert_allclose(g.inverse().matrix @ g.matrix, np.eye(3), atol=1e-15)


def test_hind_left_direction_maps_to_the_four_diagonals():
    images = {round(math.degrees(Symmetry(q).apply_direction(math.radians(-45.0))))
              for q in range(4)}
    assert images == {-45, 45, 135, -135}
    assert math.degrees(KICK_AXIS_MIRROR.apply_direction(math.radians(-45.0))) == \
        pytest.approx(-45.0)


def test_state_map_commutes_with_the_dynamics():
    rng = np.random.default_rng(5)
    model = assemble(scene_with())
    x = rest_state(model)
    x = x + rng.normal(0, 1e-9, x.size) * (np.abs(x) > 0)
    x[model.sphere_offset + 7:model.sphere_offset + 13] = rng.normal(0, 1e-2, 6)
    x[model.bristle_offset:] = rng.normal(0, 3e-10, 12)
    u = np.array([10.0, 20.0, 30.0, 40.0])
    for g in all_symmetries():
        gu = np.zeros(4)
        for beam, image in g.beam_map().items():
            gu[image - 1] = u[beam - 1]
        lhs = model.rhs(0.0, g.apply_state(model, x), gu)
        rhs = g.apply_state(model, model.rhs(0.0, x, u))
        # The quaternion's rate is not a state image; compare everything else.
        o = model.sphere_offset
        keep = np.r_[0:o + 3, o + 7:model.n_states]
        np.testing.assert_allclose(lhs[keep], rhs[keep], rtol=1e-7, atol=1e-9)


@pytest.mark.parametrize('g', [Symmetry(1), Symmetry(2, True)])
def test_simulated_kick_images_agree(g):
    model = assemble(scene_with())
    x0 = rest_state(model)
    programme = all_beams([35, 35, 80, 80], 3e-3)
    a = simulate(model, x0, 8e-3, programme, rtol=1e-8, sample_period_s=1e-3).surface_normal()
    b = simulate(model, x0, 8e-3, g.apply_programme(programme), rtol=1e-8,
                 sample_period_s=1e-3).surface_normal()
    assert np.max(np.abs(a[:2])) > 1e-5
    np.testing.assert_allclose(b, g.apply_vector(a), atol=1e-6 * np.max(np.abs(a[:2])) + 1e-9)
