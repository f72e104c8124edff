"""The model is assembled from what the scene declares, and nothing else runs."""

import dataclasses

import numpy as np
import pytest
from physics_helpers import scene_with

from sphere_sim.model import dynamics
from sphere_sim.model.assembly import assemble


def _raise(*args, **kwargs):
    raise AssertionError('a part the scene left out was evaluated')


def _random_state(model, rng):
    x = np.zeros(model.n_states)
    n = model.n_beams
    x[0:2 * n:2] = rng.uniform(-3e-6, 3e-6, n)
    x[1:2 * n:2] = rng.uniform(-5e-3, 5e-3, n)
    x[2 * n:4 * n] = rng.normal(0, 1e-2, 2 * n)
    return x


def test_beams_only_scene_has_two_dof_per_beam():
    for beams in ([1], [1, 3], [1, 2, 3, 4]):
        model = assemble(scene_with(beams=beams, sphere=False))
        assert model.n_states == 4 * len(beams)
        assert 'sphere' not in model.parts and 'sphere_contact' not in model.parts
        assert not any(part.startswith('friction') for part in model.parts)


def test_full_scene_has_sphere_states_and_all_parts():
    model = assemble(scene_with())
    assert model.n_states == 4 * 4 + 13 + 4 * 3  # beams, sphere, a friction bristle per tip
    assert model.parts == ('beams', 'electrostatics:closed_form', 'ground_contact', 'sphere',
                           'sphere_contact', 'friction:viscous', 'friction:coulomb',
                           'friction:stribeck', 'friction:stiction')


def test_a_scene_without_stiction_has_no_bristles_and_slides_by_the_papers_law():
    """``effects.friction.stiction: false`` (the ``sliding`` rung) drops the bristles' states
    and their part; the tips then feel eq. (46)-(48) regularised by eq. (51), the ``paper``
    reading's sliding force at sqrt(eps + v^2)."""
    from sphere_sim.model import dynamics as dyn
    from sphere_sim.model.friction import paper_sliding_force

    scene = scene_with()
    model = assemble(scene.replace(effects=dataclasses.replace(scene.effects, stiction=False)))
    assert model.n_states == 4 * 4 + 13 and not model.has_bristles
    assert 'friction:stiction' not in model.parts and 'friction:coulomb' in model.parts
    f = model.params.friction
    for speed in (0.0, 1e-5, 3e-3, 0.1, 0.3):
        regularised = np.sqrt(f.epsilon_m2_per_s2 + speed**2)
        got = dyn.friction_magnitude(regularised, 2e-3, 1.0, f.viscous_ns_per_m, f.coulomb,
                                     f.coulomb_velocity_m_per_s, f.stribeck,
                                     f.stribeck_velocity_m_per_s, True, True, True,
                                     model.flags[dyn.F_FRICTION_READING])
        assert got == pytest.approx(paper_sliding_force(
            regularised, 2e-3, 1.0, f.viscous_ns_per_m, f.coulomb, f.coulomb_velocity_m_per_s,
            f.stribeck, f.stribeck_velocity_m_per_s), rel=1e-12)
        assert got > 0.0


@pytest.mark.parametrize('patched', ['quat_rows', 'friction_magnitude', 'onset_gate'])
def test_beams_only_scene_never_calls_sphere_or_friction_code(monkeypatch, patched):
    rng = np.random.default_rng(1)
    model = assemble(scene_with(sphere=False), jit=False)
    x = _random_state(model, rng)
    monkeypatch.setattr(dynamics, patched, _raise)
    dxdt = model.rhs(0.0, x, np.full(4, 30.0))
    assert np.all(np.isfinite(dxdt))


def test_parts_switched_off_are_never_called(monkeypatch):
    rng = np.random.default_rng(2)
    model = assemble(scene_with(sphere=False, ground_contact=False, electrostatics=False),
                     jit=False)
    x = _random_state(model, rng)
    x[0:8:2] = -9.5e-6  # deep in what would be ground contact
    for name in ('contact_force', 'capacitance_of', 'quat_rows', 'friction_magnitude'):
        monkeypatch.setattr(dynamics, name, _raise)
    assert np.all(np.isfinite(model.rhs(0.0, x, np.full(4, 80.0))))


def test_patched_part_is_detected_when_the_scene_needs_it(monkeypatch):
    # Guards the two tests above: the patch really intercepts the kernel's calls.
    model = assemble(scene_with(), jit=False)
    x = np.zeros(model.n_states)
    x[model.sphere_offset + 3] = 1.0
    monkeypatch.setattr(dynamics, 'quat_rows', _raise)
    with pytest.raises(AssertionError, match='left out'):
        model.rhs(0.0, x, np.zeros(4))


def test_compiled_and_python_kernels_agree():
    rng = np.random.default_rng(3)
    scene = scene_with()
    fast, slow = assemble(scene), assemble(scene, jit=False)
    from sphere_sim.model.initial_state import rest_state

    x = rest_state(fast)
    x = x + 1e-9 * rng.normal(size=x.size) * (np.abs(x) > 0)
    x[fast.sphere_offset + 7:fast.sphere_offset + 13] += rng.normal(0, 1e-3, 6)
    x[fast.bristle_offset:] += rng.normal(0, 3e-10, 12)
    u = np.array([35.0, 35.0, 80.0, 80.0])
    np.testing.assert_allclose(fast.rhs(0, x, u), slow.rhs(0, x, u), rtol=1e-9, atol=1e-12)


def test_a_scene_has_one_parameter_set_whichever_way_it_is_asked_for():
    """``assemble(scene, base)`` runs on ``scene.parameters(base)``: the scene's perturbation
    holds with a replacement set too, as with the set the scene names."""
    from sphere_sim.model.parameters import load_parameter_set

    scene = scene_with().replace(perturbation=(('beam.stiffness_phi_nm_per_rad', 2.5e-6),))
    base = load_parameter_set('table_a1')
    for replacement in (None, base):
        model = assemble(scene, replacement, jit=False)
        assert model.params == scene.parameters(replacement)
        assert model.params.beam.stiffness_phi_nm_per_rad == 2.5e-6
    assert assemble(scene, base, jit=False).params.name == base.name


def test_one_table_gives_every_packed_quantity_its_index_and_its_value():
    """sphere_sim.model.packed: indices 0..N-1 in the table's order, each quantity read from
    its path (none twice), the derived ones computed by the assembly."""
    from sphere_sim.model.assembly import pack_parameters
    from sphere_sim.model.packed import DERIVED, N_PARAMS, Packed
    from sphere_sim.model.parameters import load_parameter_set

    assert [int(q) for q in Packed] == list(range(N_PARAMS))
    paths = [q.path for q in Packed if q.path != DERIVED]
    assert len(paths) == len(set(paths))
    params = load_parameter_set('calibrated')
    p = pack_parameters(params)
    assert p.shape == (N_PARAMS,)
    for quantity in Packed:
        if quantity.path != DERIVED:
            assert p[quantity] == params.get(quantity.path), quantity.name
    assert np.all(p[Packed.JXX:Packed.JZZ + 1] > 0.0)  # the flattened sphere's inertia
    model = assemble(scene_with())
    np.testing.assert_array_equal(model.p[Packed.JXX:Packed.JZZ + 1],
                                  p[Packed.JXX:Packed.JZZ + 1])
