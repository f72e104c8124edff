"""The Newton systems with the kinematic states eliminated, and the Jacobian's beam columns."""

import numpy as np
import pytest
from physics_helpers import scene_with

from sphere_sim.integrate import block_lu, newton_system
from sphere_sim.integrate import radau_compiled as rc
from sphere_sim.model import dynamics as dyn
from sphere_sim.model.assembly import assemble
from sphere_sim.model.initial_state import rest_state
from sphere_sim.model.scaling import state_scale
from sphere_sim.model.scene import load_scene

MU = (rc.MU_REAL, complex(rc.MU_COMPLEX_RE, rc.MU_COMPLEX_IM))
STEPS_S = (1e-8, 1e-6, 1e-4)  # the step sizes the compiled Radau takes


def reduced_layout(model):
    pos, vel, *reduced = newton_system.model_layout(model.flags, model.n_states)
    return (pos, vel), tuple(reduced)


def position_columns(jac, red, pos):
    out = np.empty((red.size, pos.size))
    newton_system.position_columns(jac, red, pos, out)
    return out


@pytest.fixture(scope='module')
def kick_states(model, kick_trajectory):
    """(model, states, voltages) along the optimised kick (conftest.kick_trajectory)."""
    return model, kick_trajectory.x.T, kick_trajectory.u.T


@pytest.mark.parametrize('sphere', [True, False])
def test_kinematic_pairs_are_exact_in_the_kernel(sphere):
    model = assemble(scene_with(sphere=sphere))
    pos, vel = dyn.kinematic_pairs(model.flags)
    assert pos.size == 2 * model.n_beams + (3 if sphere else 0)
    rng = np.random.default_rng(5)
    x0 = rest_state(model)
    for _ in range(5):
        x = x0 + 0.3 * state_scale(model) * rng.standard_normal(model.n_states)
        f = model.rhs(0.0, x, np.array([35.0, 35.0, 80.0, 80.0]))
        np.testing.assert_array_equal(f[pos], x[vel])


def test_the_reduced_system_keeps_two_rates_and_a_bristle_per_beam_and_the_sphere_border():
    model = assemble(load_scene('rest'))
    (pos, vel), (red, pos_of, start, end, tail) = reduced_layout(model)
    assert red.size == model.n_states - 11 == 30
    assert not set(red) & set(pos)
    assert tail == 20
    np.testing.assert_array_equal(start[:20], np.repeat([0, 5, 10, 15], 5))
    np.testing.assert_array_equal(end[:20], np.repeat([5, 10, 15, 20], 5))
    # Each block: the beam's two rates, then its tip's three bristle states.
    bristles = model.bristle_offset + 3 * np.arange(4)
    np.testing.assert_array_equal(red[2:20:5], bristles)
    # Each rate knows its position; the quaternion and the angular velocity have none.
    for a, k in enumerate(red):
        expected = pos[list(vel).index(k)] if k in vel else -1
        assert pos_of[a] == expected


def test_reduced_solve_equals_the_full_newton_system_along_a_kick(kick_states):
    model, states, voltages = kick_states
    (pos, vel), (red, pos_of, start, end, tail) = reduced_layout(model)
    n, m = model.n_states, red.size
    dense = block_lu.dense_structure(m)
    rng = np.random.default_rng(6)
    worst = worst_backward = 0.0
    for x, u in zip(states, voltages, strict=True):
        jac = model.jacobian(0.0, x, u)
        assert newton_system.is_arrow(jac, red, pos_of, start, end, tail)
        full = jac.copy()
        full[pos] = np.eye(n)[vel]  # what the reduction assumes of the position rows
        for mu in MU:
            for h in STEPS_S:
                gamma = mu / h
                dtype = np.result_type(gamma, float)
                lu = np.empty((m, m), dtype=dtype)
                piv = np.empty(m, dtype=np.int64)
                ok, *structure = newton_system.factor(jac, gamma, red, pos_of, lu, piv, True,
                                                      start, end, tail, *dense)
                assert ok and structure[2] == tail  # the block-arrow factorisation held
                b = rng.standard_normal(n).astype(dtype)
                d = b.copy()
                newton_system.solve(lu, piv, position_columns(jac, red, pos), gamma, d, red,
                                    pos, vel, np.empty(m, dtype=dtype), *structure)
                matrix = gamma * np.eye(n) - full
                exact = np.linalg.solve(matrix, b)
                worst = max(worst, np.max(np.abs(d - exact)) / np.max(np.abs(exact)))
                backward = (np.max(np.abs(matrix @ d - b))
                            / (np.max(np.abs(matrix)) * np.max(np.abs(d)) + np.max(np.abs(b))))
                worst_backward = max(worst_backward, backward)
    # The solve is backward stable (measured 1e-16 and below); against the dense solve of a
    # matrix whose bristle rows reach 1e6 /s over metres of 1e-10 it agrees to 1e-9 (measured
    # 9.9e-10, the conditioning's share); the Newton iteration needs far less.
    assert worst_backward < 1e-13
    assert worst < 1e-8


def test_paired_factor_and_solve_equal_the_real_and_complex_apart(kick_states):
    """Radau's real and complex systems factored and solved in one pass (factor_pair,
    solve_pair) give what they give apart: the same operations in the same order."""
    model, states, voltages = kick_states
    (pos, vel), (red, pos_of, start, end, tail) = reduced_layout(model)
    n, m = model.n_states, red.size
    dense = block_lu.dense_structure(m)
    rng = np.random.default_rng(7)
    for x, u in zip(states[::5], voltages[::5], strict=True):
        jac = model.jacobian(0.0, x, u)
        j_rp = position_columns(jac, red, pos)
        for h in STEPS_S:
            gammas = (MU[0] / h, MU[1] / h)
            lus = [np.empty((m, m), dtype=np.result_type(g, float)) for g in gammas]
            pivs = [np.empty(m, dtype=np.int64) for _ in gammas]
            for lu, piv, gamma in zip(lus, pivs, gammas, strict=True):
                ok, *structure = newton_system.factor(jac, gamma, red, pos_of, lu, piv, True,
                                                      start, end, tail, *dense)
                assert ok and structure[2] == tail
            lu_r, lu_c = np.empty_like(lus[0]), np.empty_like(lus[1])
            piv_r, piv_c = np.empty(m, dtype=np.int64), np.empty(m, dtype=np.int64)
            ok, real, cplx = newton_system.factor_pair(jac, *gammas, red, pos_of, lu_r, piv_r,
                                                       lu_c, piv_c, True, start, end, tail,
                                                       *dense)
            assert ok and real[2] == cplx[2] == tail
            np.testing.assert_array_equal(lu_r, lus[0])
            np.testing.assert_array_equal(lu_c, lus[1])
            np.testing.assert_array_equal(piv_r, pivs[0])
            np.testing.assert_array_equal(piv_c, pivs[1])
            b_real = rng.standard_normal(n)
            b_complex = rng.standard_normal(n) + 1j * rng.standard_normal(n)
            apart = [b_real.copy(), b_complex.copy()]
            for lu, piv, gamma, d in zip(lus, pivs, gammas, apart, strict=True):
                newton_system.solve(lu, piv, j_rp, gamma, d, red, pos, vel,
                                    np.empty(m, dtype=d.dtype), start, end, tail)
            d_real, d_complex = b_real.copy(), b_complex.copy()
            newton_system.solve_pair(lu_r, piv_r, lu_c, piv_c, j_rp, *gammas, d_real,
                                     d_complex, red, pos, vel, np.empty(m),
                                     np.empty(m, dtype=complex), real, cplx)
            np.testing.assert_array_equal(d_real, apart[0])
            np.testing.assert_array_equal(d_complex, apart[1])


@pytest.mark.parametrize('sphere', [True, False])
def test_paired_solve_of_an_arrow_and_a_dense_factorisation(sphere):
    """When only one of the pair factored block-arrow, solve_pair gives what the two solves
    give apart. Without the sphere neither structure has a border and their tails are
    equal; the block-diagonal matrix's dense factors then solve alike with either."""
    model = assemble(scene_with(sphere=sphere))
    (pos, vel), (red, pos_of, start, end, tail) = reduced_layout(model)
    n, m = model.n_states, red.size
    dense = block_lu.dense_structure(m)
    rng = np.random.default_rng(8)
    x = rest_state(model) + 0.3 * state_scale(model) * rng.standard_normal(n)
    jac = model.jacobian(0.0, x, np.array([35.0, 35.0, 80.0, 80.0]))
    j_rp = position_columns(jac, red, pos)
    gammas = (MU[0] / STEPS_S[1], MU[1] / STEPS_S[1])
    lu_r, lu_c = np.empty((m, m)), np.empty((m, m), dtype=complex)
    piv_r, piv_c = np.empty(m, dtype=np.int64), np.empty(m, dtype=np.int64)
    ok, *real = newton_system.factor(jac, gammas[0], red, pos_of, lu_r, piv_r, True, start,
                                     end, tail, *dense)
    assert ok and real[1][0] < m  # block-arrow
    ok, *cplx = newton_system.factor(jac, gammas[1], red, pos_of, lu_c, piv_c, False, start,
                                     end, tail, *dense)
    assert ok and cplx[1][0] == m  # dense
    assert (real[2] == cplx[2]) is not sphere
    b_real = rng.standard_normal(n)
    b_complex = rng.standard_normal(n) + 1j * rng.standard_normal(n)
    apart = [b_real.copy(), b_complex.copy()]
    for lu, piv, gamma, d, structure in zip((lu_r, lu_c), (piv_r, piv_c), gammas, apart,
                                            (real, cplx), strict=True):
        newton_system.solve(lu, piv, j_rp, gamma, d, red, pos, vel,
                            np.empty(m, dtype=d.dtype), *structure)
    newton_system.solve_pair(lu_r, piv_r, lu_c, piv_c, j_rp, *gammas, b_real, b_complex, red,
                             pos, vel, np.empty(m), np.empty(m, dtype=complex), tuple(real),
                             tuple(cplx))
    np.testing.assert_array_equal(b_real, apart[0])
    np.testing.assert_array_equal(b_complex, apart[1])


def test_is_arrow_sees_coupling_between_beams_through_rates_and_positions(kick_states):
    model, states, voltages = kick_states
    _, (red, pos_of, start, end, tail) = reduced_layout(model)
    jac = model.jacobian(0.0, states[4], voltages[4])
    assert newton_system.is_arrow(jac, red, pos_of, start, end, tail)
    n = model.n_beams
    for column in (2 * n + 2, 2):  # beam 1's z rate, then its z: both seen from beam 0's row
        coupled = jac.copy()
        coupled[2 * n, column] = 1e-30
        assert not newton_system.is_arrow(coupled, red, pos_of, start, end, tail)


def test_columns_equal_differences_of_whole_kernel_calls(kick_states):
    """The Jacobian differences, for each column, only the terms that depend on that state
    (a beam alone, or the sphere-dependent terms): its columns must be the forward
    differences of the whole kernel, rounding aside."""
    model, states, voltages = kick_states
    scale = state_scale(model)
    worst = 0.0
    for x, u in zip(states[::8], voltages[::8], strict=True):
        f0 = model.rhs(0.0, x, u)
        whole = np.empty((model.n_states, model.n_states))
        for j in range(model.n_states):
            h = dyn._difference_step(x[j], scale[j], dyn.JACOBIAN_STEP)
            xp = x.copy()
            xp[j] += h
            whole[:, j] = (model.rhs(0.0, xp, u) - f0) / h
        jac = model.jacobian(0.0, x, u)
        worst = max(worst, np.max(np.abs(jac - whole)) / np.max(np.abs(whole)))
    # Measured 8e-12, in the beams' rows of the sphere's columns, where the whole kernel adds
    # the tip's force to the beam's own forces before differencing. The differences
    # themselves change by 3e-6 to 7e-5 of the same scale between steps h and 2h.
    assert worst < 1e-10
