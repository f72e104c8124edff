"""The linear systems of Radau's simplified Newton iteration, with the kinematic states
eliminated.

Each Newton iteration solves ``(gamma I - J) d = r`` with ``gamma = mu / h`` for the real
eigenvalue of the method and for its complex pair. Eleven of the model's 41 states (29 without
the friction bristles) are positions whose derivative *is* another state (dz_S/dt = z_S dot,
dxi_S/dt = v_S: :func:`sphere_sim.model.dynamics.kinematic_pairs`). Their rows of J are unit
vectors, so a position row reads ``gamma d_i - d_v(i) = r_i`` with ``v(i)`` its velocity, and gives
``d_i = (r_i + d_v(i)) / gamma``. Substituted into the remaining rows R it leaves ::

    (gamma I - J_RR - J_RP' / gamma) d_R = r_R + J_RP r_P / gamma

where ``J_RP'`` holds the column of each position at the place of its velocity. That is 30
unknowns instead of 41 (18 instead of 29 without bristles); without bristles, cycle counters put
a pair of factorisations (real and complex) at 8 000 instead of 20 000 cycles along a kick and a
pair of solves at 3 700 instead of 5 300 (docs/numerics.md). Hairer's
RADAU5 makes the same reduction for second-order systems (its M1, M2 options), where the
positions come first; here they are found by index. The position rows of J are never
used, so the finite-difference Jacobian's rounding there (``(v + h) - v`` over h) drops out.

The reduced matrix keeps the model's block-arrow form (:mod:`sphere_sim.integrate.block_lu`), with
each beam's two rates (and its tip's bristle) as its block and the sphere's quaternion and rates
as the border.
"""

import numba
import numpy as np

from sphere_sim.integrate import block_lu
from sphere_sim.model import dynamics as dyn


@numba.njit(cache=True)
def layout(n, pos, vel, perm, block_start, block_end, tail):
    """The reduced system's order and block structure.

    Parameters
    ----------
    n : int
        Number of states.
    pos, vel : ndarray of int64, shape (p,)
        Model indices with d x[pos[i]]/dt = x[vel[i]].
    perm, block_start, block_end, tail
        The full system's order and structure (:func:`sphere_sim.integrate.block_lu.arrow_order`).

    Returns
    -------
    red : ndarray of int64, shape (n - p,)
        Model index of each unknown of the reduced system, in ``perm``'s order.
    pos_of : ndarray of int64, shape (n - p,)
        Model index of the position whose rate ``red[a]`` is, or -1.
    r_start, r_end : ndarray of int64, shape (n - p,)
    r_tail : int
        The reduced block structure: ``perm``'s with the positions' rows removed.
    """
    eliminated = np.zeros(n, dtype=np.bool_)
    position_of = np.full(n, -1, dtype=np.int64)
    for i in range(pos.size):
        eliminated[pos[i]] = True
        position_of[vel[i]] = pos[i]
    kept_before = np.zeros(n + 1, dtype=np.int64)  # kept rows among perm[:i]
    for i in range(n):
        kept_before[i + 1] = kept_before[i] + (0 if eliminated[perm[i]] else 1)
    m = kept_before[n]
    red = np.empty(m, dtype=np.int64)
    pos_of = np.empty(m, dtype=np.int64)
    r_start = np.empty(m, dtype=np.int64)
    r_end = np.empty(m, dtype=np.int64)
    for i in range(n):
        if eliminated[perm[i]]:
            continue
        a = kept_before[i]
        red[a] = perm[i]
        pos_of[a] = position_of[perm[i]]
        r_start[a] = kept_before[block_start[i]]
        r_end[a] = kept_before[block_end[i]]
    return red, pos_of, r_start, r_end, kept_before[tail]


@numba.njit(cache=True)
def model_layout(flags, n):
    """:func:`layout` of an assembled model: ``(pos, vel, red, pos_of, r_start, r_end,
    r_tail)`` from :func:`sphere_sim.model.dynamics.kinematic_pairs` and the model's block-arrow
    order."""
    pos, vel = dyn.kinematic_pairs(flags)
    bristles = dyn.BRISTLE_STATES if flags[dyn.F_STICTION] else 0
    perm, start, end, tail = block_lu.arrow_order(flags[dyn.F_N_BEAMS], n, bristles)
    red, pos_of, r_start, r_end, r_tail = layout(n, pos, vel, perm, start, end, tail)
    return pos, vel, red, pos_of, r_start, r_end, r_tail


@numba.njit(cache=True)
def is_arrow(J, red, pos_of, block_start, block_end, tail):
    """True if the reduced matrix of ``J`` (model order) is zero between different blocks."""
    for a in range(tail):
        k = red[a]
        for b in range(tail):
            if block_start[a] <= b < block_end[a]:
                continue
            if J[k, red[b]] != 0.0 or (pos_of[b] >= 0 and J[k, pos_of[b]] != 0.0):
                return False
    return True


@numba.njit(cache=True)
def matrix(J, mu_over_h, red, pos_of, out):
    """``out = gamma I - J_RR - J_RP' / gamma`` (module docstring), real or complex."""
    m = red.size
    inv = 1.0 / mu_over_h
    for a in range(m):
        k = red[a]
        for b in range(m):
            out[a, b] = -J[k, red[b]]
            if pos_of[b] >= 0:
                out[a, b] -= J[k, pos_of[b]] * inv
        out[a, a] += mu_over_h


@numba.njit(cache=True)
def matrix_pair(J, mu_real_over_h, mu_complex_over_h, red, pos_of, out_real, out_complex):
    """:func:`matrix` for the real and the complex ``gamma`` in one pass over ``J``."""
    m = red.size
    inv_real = 1.0 / mu_real_over_h
    inv_complex = 1.0 / mu_complex_over_h
    for a in range(m):
        k = red[a]
        for b in range(m):
            entry = -J[k, red[b]]
            out_real[a, b] = entry
            out_complex[a, b] = entry
            if pos_of[b] >= 0:
                coupling = J[k, pos_of[b]]
                out_real[a, b] -= coupling * inv_real
                out_complex[a, b] -= coupling * inv_complex
        out_real[a, a] += mu_real_over_h
        out_complex[a, a] += mu_complex_over_h


@numba.njit(cache=True)
def factor(J, mu_over_h, red, pos_of, LU, piv, arrow, arrow_start, arrow_end, arrow_tail,
           dense_start, dense_end, dense_tail):
    """LU of the reduced Newton matrix into ``LU``: block-arrow when the reduced matrix is one
    (``arrow``, :func:`is_arrow`) and that succeeds, dense otherwise.

    Returns ``(ok, block_start, block_end, tail)``, the structure to solve with.
    """
    if arrow:
        matrix(J, mu_over_h, red, pos_of, LU)
        if block_lu.factor(LU, piv, arrow_start, arrow_end, arrow_tail,
                           block_lu.PIVOT_THRESHOLD):
            return True, arrow_start, arrow_end, arrow_tail
    matrix(J, mu_over_h, red, pos_of, LU)
    ok = block_lu.factor(LU, piv, dense_start, dense_end, dense_tail, 0.0)
    return ok, dense_start, dense_end, dense_tail


@numba.njit(cache=True)
def factor_pair(J, mu_real_over_h, mu_complex_over_h, red, pos_of, LU_real, piv_real,
                LU_complex, piv_complex, arrow, arrow_start, arrow_end, arrow_tail,
                dense_start, dense_end, dense_tail):
    """:func:`factor` of Radau's real and complex Newton matrices; in one pass
    (:func:`sphere_sim.integrate.block_lu.factor_pair`) when both are block-arrow.

    Returns ``(ok, real structure, complex structure)``, each structure a
    ``(block_start, block_end, tail)``; ``ok`` is False if either factorisation failed.
    """
    if arrow:
        matrix_pair(J, mu_real_over_h, mu_complex_over_h, red, pos_of, LU_real, LU_complex)
        if block_lu.factor_pair(LU_real, piv_real, LU_complex, piv_complex, arrow_start,
                                arrow_end, arrow_tail, block_lu.PIVOT_THRESHOLD):
            return (True, (arrow_start, arrow_end, arrow_tail),
                    (arrow_start, arrow_end, arrow_tail))
    ok_r, start_r, end_r, tail_r = factor(J, mu_real_over_h, red, pos_of, LU_real, piv_real,
                                          arrow, arrow_start, arrow_end, arrow_tail,
                                          dense_start, dense_end, dense_tail)
    ok_c, start_c, end_c, tail_c = factor(J, mu_complex_over_h, red, pos_of, LU_complex,
                                          piv_complex, arrow, arrow_start, arrow_end,
                                          arrow_tail, dense_start, dense_end, dense_tail)
    return ok_r and ok_c, (start_r, end_r, tail_r), (start_c, end_c, tail_c)


@numba.njit(cache=True)
def position_columns(J, red, pos, out):
    """``out[a, i] = J[red[a], pos[i]]``: the columns J_RP that :func:`solve` multiplies,
    gathered once per Jacobian (shape (n - p, p))."""
    for a in range(red.size):
        k = red[a]
        for i in range(pos.size):
            out[a, i] = J[k, pos[i]]


@numba.njit(cache=True)
def solve(LU, piv, J_RP, mu_over_h, r, red, pos, vel, work, block_start, block_end, tail):
    """Solve ``(gamma I - J) d = r`` in place in ``r`` (model order, shape (n,)).

    ``LU``, ``piv`` and the structure come from :func:`factor` with the same ``J`` and
    ``mu_over_h``; ``J_RP`` from :func:`position_columns`; ``work`` is scratch of shape
    (n - p,) and ``r``'s dtype.
    """
    inv = 1.0 / mu_over_h
    for a in range(red.size):
        acc = 0.0 * r[0]  # zero of r's dtype
        for i in range(pos.size):
            acc += J_RP[a, i] * r[pos[i]]
        work[a] = r[red[a]] + acc * inv
    block_lu.solve(LU, piv, work, block_start, block_end, tail)
    for a in range(red.size):
        r[red[a]] = work[a]
    for i in range(pos.size):
        r[pos[i]] = (r[pos[i]] + r[vel[i]]) * inv


@numba.njit(cache=True)
def solve_pair(LU_real, piv_real, LU_complex, piv_complex, J_RP, mu_real_over_h,
               mu_complex_over_h, r_real, r_complex, red, pos, vel, work_real, work_complex,
               structure_real, structure_complex):
    """:func:`solve` of Radau's real and complex systems with the structures
    :func:`factor_pair` returned. When both are the same (both block-arrow, or both dense),
    in one pass: each entry of ``J_RP`` and of the structure is loaded once for both, and
    their substitutions run side by side (:func:`sphere_sim.integrate.block_lu.solve_pair`)."""
    block_start, block_end, tail = structure_real
    # Block-arrow and dense differ in their tail, except without the sphere, where neither
    # has a border: the matrix is then block-diagonal (is_arrow), its dense factors keep
    # the blocks' zeros, and the block structure solves either factorisation alike.
    if tail != structure_complex[2]:
        solve(LU_real, piv_real, J_RP, mu_real_over_h, r_real, red, pos, vel, work_real,
              *structure_real)
        solve(LU_complex, piv_complex, J_RP, mu_complex_over_h, r_complex, red, pos, vel,
              work_complex, *structure_complex)
        return
    inv_real = 1.0 / mu_real_over_h
    inv_complex = 1.0 / mu_complex_over_h
    for a in range(red.size):
        acc_real = 0.0
        acc_re = 0.0
        acc_im = 0.0
        for i in range(pos.size):
            c = J_RP[a, i]
            q = pos[i]
            acc_real += c * r_real[q]
            acc_re += c * r_complex[q].real
            acc_im += c * r_complex[q].imag
        k = red[a]
        work_real[a] = r_real[k] + acc_real * inv_real
        work_complex[a] = r_complex[k] + complex(acc_re, acc_im) * inv_complex
    block_lu.solve_pair(LU_real, piv_real, work_real, LU_complex, piv_complex, work_complex,
                        block_start, block_end, tail)
    for a in range(red.size):
        r_real[red[a]] = work_real[a]
        r_complex[red[a]] = work_complex[a]
    for i in range(pos.size):
        r_real[pos[i]] = (r_real[pos[i]] + r_real[vel[i]]) * inv_real
        r_complex[pos[i]] = (r_complex[pos[i]] + r_complex[vel[i]]) * inv_complex
