"""Allocation-free 3-vector algebra on tuples for the compiled kernels."""

import numba


@numba.njit(cache=True, inline='always')
def dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@numba.njit(cache=True, inline='always')
def cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


@numba.njit(cache=True, inline='always')
def add(a, b):
    return (a[0] + b[0], a[1] + b[1], a[2] + b[2])


@numba.njit(cache=True, inline='always')
def sub(a, b):
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


@numba.njit(cache=True, inline='always')
def scale(s, a):
    return (s * a[0], s * a[1], s * a[2])


@numba.njit(cache=True, inline='always')
def matvec(R, a):
    """R a for a matrix ``R`` given as a tuple of three row tuples."""
    return (R[0][0] * a[0] + R[0][1] * a[1] + R[0][2] * a[2],
            R[1][0] * a[0] + R[1][1] * a[1] + R[1][2] * a[2],
            R[2][0] * a[0] + R[2][1] * a[1] + R[2][2] * a[2])


@numba.njit(cache=True, inline='always')
def mat_t_vec(R, a):
    """R^T a for a matrix ``R`` given as a tuple of three row tuples."""
    return (R[0][0] * a[0] + R[1][0] * a[1] + R[2][0] * a[2],
            R[0][1] * a[0] + R[1][1] * a[1] + R[2][1] * a[2],
            R[0][2] * a[0] + R[1][2] * a[1] + R[2][2] * a[2])
