"""LU factorisation of the Newton matrices, dense or in the model's block-arrow form.

A beam's equations depend on its own state and the sphere's, never on another beam's, so with
each beam's four states grouped and the sphere's thirteen last, the Jacobian (and the Newton
matrix ``mu / h I - J``) is a *block arrow*: 4x4 beam blocks on the diagonal, zero between
beams, a dense border of sphere rows and columns. Eliminating a beam's columns then touches
only that beam's rows and the sphere's. For four beams and the sphere (29 states) that saves
about a quarter of a factorisation and solve (1.7 against 2.2 µs real, 3.5 against 4.6 µs
complex, measured along a kick); the dense routine already skipped zero rows.

One routine serves both: a structure is ``(block_start, block_end, tail)`` with, for each row
``i``, its diagonal block ``[block_start[i], block_end[i])``, and the first border row
``tail``. The dense structure (one block, no border) is partial pivoting as usual. In the
arrow structure rows are exchanged only within a beam block. That is the block elimination of
a light beam against the heavy sphere it touches; its pivots are routinely 1e-6 of the border
entries of their column (a beam's spring rate k_z / m_B against the contact rate k_c / m_S),
so the usual threshold test would refuse it, yet along the optimised kick's trajectory its
solutions agree with LAPACK's to 1.4e-10 relative (test_block_lu). Only a pivot below
``PIVOT_THRESHOLD`` times the border fails it, and the caller then falls back to the dense
factorisation.
"""

import numba
import numpy as np

# A beam-block pivot smaller than this fraction of the largest border entry of its column fails
# the arrow factorisation (the dense one is used instead). Along a kick the ratios reach 1e-8
# with accurate solutions (a threshold of 1e-6 refused half of 2432 matrices, 1e-8 none); a
# ratio of 1e-12 means the block is singular to working precision.
PIVOT_THRESHOLD = 1e-12
STATES_PER_BEAM = 4


@numba.njit(cache=True, inline='always')
def _size(a):
    """|Re a| + |Im a|: LAPACK's pivot measure (cabs1), without the square root of abs."""
    return abs(a.real) + abs(a.imag)


@numba.njit(cache=True)
def dense_structure(n):
    """The trivial structure: one dense block, no border."""
    return np.zeros(n, dtype=np.int64), np.full(n, n, dtype=np.int64), n


@numba.njit(cache=True)
def arrow_order(n_beams, n, bristle_states=0):
    """Permutation that groups each beam's states and puts the sphere's last.

    A beam's block holds its four states and, with ``bristle_states`` per beam (the friction
    bristles that the model keeps after the sphere's states), its tip's bristle: a bristle
    couples only its own beam and the sphere, so the block-arrow form is kept.

    Returns
    -------
    perm : ndarray of int64, shape (n,)
        ``perm[i]`` is the model state (layout of :mod:`~sphere_sim.model.dynamics`) at
        position ``i``.
    block_start, block_end : ndarray of int64, shape (n,)
    tail : int
        First sphere position; ``n`` when there is no sphere.
    """
    perm = np.empty(n, dtype=np.int64)
    block_start = np.zeros(n, dtype=np.int64)
    block_end = np.full(n, n, dtype=np.int64)
    per_beam = STATES_PER_BEAM + bristle_states
    first_bristle = n - bristle_states * n_beams
    for k in range(n_beams):
        a = per_beam * k
        perm[a] = 2 * k
        perm[a + 1] = 2 * k + 1
        perm[a + 2] = 2 * n_beams + 2 * k
        perm[a + 3] = 2 * n_beams + 2 * k + 1
        for i in range(bristle_states):
            perm[a + STATES_PER_BEAM + i] = first_bristle + bristle_states * k + i
        for i in range(a, a + per_beam):
            block_start[i] = a
            block_end[i] = a + per_beam
    tail = per_beam * n_beams
    for i in range(tail, n):
        perm[i] = STATES_PER_BEAM * n_beams + i - tail
    return perm, block_start, block_end, tail


@numba.njit(cache=True, inline='always')
def _pivot(A, k, start, end, tail, n, piv, pivot_threshold):
    """Choose the pivot of column ``k`` among rows [k, end) and swap its row in from column
    ``start`` (the block's first) on; returns False if it is zero or, in a beam block, below
    ``pivot_threshold`` times the largest border entry of the column."""
    p = k
    best = _size(A[k, k])
    for i in range(k + 1, end):
        v = _size(A[i, k])
        if v > best:
            best = v
            p = i
    piv[k] = p
    if best == 0.0:
        return False
    if k < tail:
        border = 0.0
        for i in range(tail, n):
            border = max(border, _size(A[i, k]))
        if best < pivot_threshold * border:
            return False
    if p != k:
        for j in range(start, n):
            tmp = A[k, j]
            A[k, j] = A[p, j]
            A[p, j] = tmp
    return True


@numba.njit(cache=True)
def factor(A, piv, block_start, block_end, tail, pivot_threshold):
    """LU with partial pivoting within diagonal blocks, in place.

    Parameters
    ----------
    A : ndarray, shape (n, n), float64 or complex128
        Overwritten with L (unit diagonal, below) and U (above the diagonal, with the
        reciprocals of its diagonal on it). Entries outside the structure are taken as zero
        and left alone.
    piv : ndarray of int64, shape (n,)
        Row interchanges.
    block_start, block_end, tail
        The structure (module docstring).
    pivot_threshold : float
        Smallest ratio of a beam-block pivot to the largest border entry of its column.

    Returns
    -------
    bool
        False if a pivot is zero or, in a beam block, below the threshold.
    """
    n = A.shape[0]
    for k in range(n):
        end = block_end[k]
        if not _pivot(A, k, block_start[k], end, tail, n, piv, pivot_threshold):
            return False
        inv = 1.0 / A[k, k]
        A[k, k] = inv  # solve multiplies by it: a complex division costs several products
        border_start = max(tail, end)
        for i in range(k + 1, n):
            if end <= i < border_start:
                continue
            a = A[i, k] * inv
            A[i, k] = a
            if a != 0.0:
                for j in range(k + 1, end):
                    A[i, j] -= a * A[k, j]
                for j in range(border_start, n):
                    A[i, j] -= a * A[k, j]
    return True


@numba.njit(cache=True)
def factor_pair(A, piv_a, B, piv_b, block_start, block_end, tail, pivot_threshold):
    """:func:`factor` of two matrices of the same structure, in one pass.

    The eliminations run side by side (Radau's real and complex Newton matrices), as in
    :func:`solve_pair`. Returns False if either fails; both are then to be factored apart.
    """
    n = A.shape[0]
    for k in range(n):
        end = block_end[k]
        start = block_start[k]
        if not (_pivot(A, k, start, end, tail, n, piv_a, pivot_threshold)
                and _pivot(B, k, start, end, tail, n, piv_b, pivot_threshold)):
            return False
        inv_a = 1.0 / A[k, k]
        inv_b = 1.0 / B[k, k]
        A[k, k] = inv_a
        B[k, k] = inv_b
        border_start = max(tail, end)
        for i in range(k + 1, n):
            if end <= i < border_start:
                continue
            a = A[i, k] * inv_a
            b = B[i, k] * inv_b
            A[i, k] = a
            B[i, k] = b
            if a != 0.0 or b != 0.0:
                for j in range(k + 1, end):
                    A[i, j] -= a * A[k, j]
                    B[i, j] -= b * B[k, j]
                for j in range(border_start, n):
                    A[i, j] -= a * A[k, j]
                    B[i, j] -= b * B[k, j]
    return True


@numba.njit(cache=True, inline='always')
def _interchange(b, piv):
    """Apply the factorisation's row interchanges to ``b``, in order."""
    for k in range(b.size):
        p = piv[k]
        if p != k:
            tmp = b[k]
            b[k] = b[p]
            b[p] = tmp


@numba.njit(cache=True)
def solve(LU, piv, b, block_start, block_end, tail):
    """Solve A x = b in place in ``b`` from :func:`factor`'s output (same structure)."""
    n = LU.shape[0]
    _interchange(b, piv)
    for i in range(n):
        acc = b[i]
        for j in range(block_start[i], i):
            acc -= LU[i, j] * b[j]
        b[i] = acc
    for i in range(n - 1, -1, -1):
        acc = b[i]
        end = block_end[i]
        for j in range(i + 1, end):
            acc -= LU[i, j] * b[j]
        for j in range(max(tail, end), n):
            acc -= LU[i, j] * b[j]
        b[i] = acc * LU[i, i]


@numba.njit(cache=True)
def solve_pair(LU_a, piv_a, b_a, LU_b, piv_b, b_b, block_start, block_end, tail):
    """:func:`solve` of two systems factored with the same structure, in one pass.

    Each substitution is a chain of dependent multiply-adds; running the two chains side by
    side (Radau's real and complex systems) keeps the processor busy while either waits.
    """
    n = LU_a.shape[0]
    _interchange(b_a, piv_a)
    _interchange(b_b, piv_b)
    for i in range(n):
        acc_a = b_a[i]
        acc_b = b_b[i]
        for j in range(block_start[i], i):
            acc_a -= LU_a[i, j] * b_a[j]
            acc_b -= LU_b[i, j] * b_b[j]
        b_a[i] = acc_a
        b_b[i] = acc_b
    for i in range(n - 1, -1, -1):
        acc_a = b_a[i]
        acc_b = b_b[i]
        end = block_end[i]
        for j in range(i + 1, end):
            acc_a -= LU_a[i, j] * b_a[j]
            acc_b -= LU_b[i, j] * b_b[j]
        for j in range(max(tail, end), n):
            acc_a -= LU_a[i, j] * b_a[j]
            acc_b -= LU_b[i, j] * b_b[j]
        b_a[i] = acc_a * LU_a[i, i]
        b_b[i] = acc_b * LU_b[i, i]
