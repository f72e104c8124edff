"""The Newton matrices' LU: dense and block-arrow factorisations against LAPACK."""

import numpy as np
import pytest

from sphere_sim.integrate import block_lu
from sphere_sim.integrate import radau_compiled as rc

# Newton matrices mu / h I - J of the compiled Radau: its real eigenvalue and complex pair,
# over the step sizes it takes (s).
MU = (rc.MU_REAL, complex(rc.MU_COMPLEX_RE, rc.MU_COMPLEX_IM))
STEPS_S = (1e-8, 1e-6, 1e-4)


def factor_and_solve(a, b, structure, threshold=block_lu.PIVOT_THRESHOLD):
    lu = a.copy()
    piv = np.empty(a.shape[0], dtype=np.int64)
    ok = block_lu.factor(lu, piv, *structure, threshold)
    x = b.copy()
    if ok:
        block_lu.solve(lu, piv, x, *structure)
    return ok, x


@pytest.mark.parametrize('dtype', [float, complex])
def test_dense_structure_solves_like_lapack(dtype):
    rng = np.random.default_rng(1)
    a = rng.standard_normal((9, 9)).astype(dtype)
    if dtype is complex:
        a = a + 1j * rng.standard_normal((9, 9))
    b = rng.standard_normal(9).astype(dtype)
    ok, x = factor_and_solve(a, b, block_lu.dense_structure(9))
    assert ok
    np.testing.assert_allclose(x, np.linalg.solve(a, b), rtol=1e-10)


def test_arrow_order_groups_each_beam():
    perm, start, end, tail = block_lu.arrow_order(2, 8 + 13)
    np.testing.assert_array_equal(perm[:8], [0, 1, 4, 5, 2, 3, 6, 7])
    np.testing.assert_array_equal(perm[8:], np.arange(8, 21))
    assert tail == 8
    np.testing.assert_array_equal(start[:8], [0, 0, 0, 0, 4, 4, 4, 4])
    np.testing.assert_array_equal(end[:8], [4, 4, 4, 4, 8, 8, 8, 8])


def test_arrow_order_puts_each_tips_bristle_in_its_beams_block():
    # Two beams, the sphere (8..20), then the bristles: beam 0's at 21..23, beam 1's at 24..26.
    perm, start, end, tail = block_lu.arrow_order(2, 8 + 13 + 6, 3)
    np.testing.assert_array_equal(perm[:14], [0, 1, 4, 5, 21, 22, 23, 2, 3, 6, 7, 24, 25, 26])
    np.testing.assert_array_equal(perm[14:], np.arange(8, 21))
    assert tail == 14
    np.testing.assert_array_equal(start[:14], np.repeat([0, 7], 7))
    np.testing.assert_array_equal(end[:14], np.repeat([7, 14], 7))


@pytest.fixture(scope='module')
def kick_jacobians(model, kick_trajectory):
    """Jacobians (arrow order) along the optimised kick, through every contact phase."""
    traj = kick_trajectory
    perm, start, end, tail = block_lu.arrow_order(model.n_beams, model.n_states,
                                                  3 if model.has_bristles else 0)
    out = []
    for k in range(traj.x.shape[1]):
        jac = model.jacobian(0.0, traj.x[:, k], traj.u[:, k])
        out.append(jac[np.ix_(perm, perm)])
    return out, (start, end, tail)


def test_the_model_jacobian_is_an_arrow(kick_jacobians):
    jacobians, (start, end, tail) = kick_jacobians
    rows = np.arange(tail)[:, None]
    between_beams = (rows < start[None, :tail]) | (rows >= end[None, :tail])
    assert all(np.all(j[:tail, :tail][between_beams] == 0.0) for j in jacobians)
    # ... and not trivially: the sphere couples to the beams through the contacts.
    assert any(np.any(j[tail:, :tail] != 0.0) for j in jacobians)


def test_arrow_solves_like_lapack_along_a_kick(kick_jacobians):
    """No pivoting across blocks: the pivots are often 1e-6 of their column's border entries
    (block_lu docstring), and the solutions must still be accurate."""
    jacobians, structure = kick_jacobians
    rng = np.random.default_rng(2)
    worst = 0.0
    for jac in jacobians:
        n = jac.shape[0]
        for mu in MU:
            for h in STEPS_S:
                a = (mu / h) * np.eye(n) - jac
                b = rng.standard_normal(n).astype(a.dtype)
                ok, x = factor_and_solve(a, b, structure)
                assert ok
                exact = np.linalg.solve(a, b)
                worst = max(worst, np.max(np.abs(x - exact)) / np.max(np.abs(exact)))
    # Measured 1.4e-10; the simplified Newton iteration needs far less.
    assert worst < 1e-8


def test_a_singular_block_fails_the_arrow_factorisation():
    _, start, end, tail = block_lu.arrow_order(1, 4 + 13)
    a = np.eye(17)
    a[:4, :4] = 0.0
    a[4:, :4] = 1.0
    ok, _ = factor_and_solve(a, np.ones(17), (start, end, tail))
    assert not ok
