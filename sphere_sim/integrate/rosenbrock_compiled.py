"""A compiled Rosenbrock W-method for the assembled model: ROS34PW2 (order 3, L-stable).

ROS34PW2 (J. Rang and L. Angermann, "New Rosenbrock W-methods of order 3 for partial
differential algebraic equations of index 1", BIT Numerical Mathematics 45 (2005) 761-787,
Table 4.3 there): four stages, order 3 with an embedded method of order 2, L-stable, and a
*W-method*: its order conditions hold for any matrix in place of the Jacobian, so a Jacobian
may be kept over several steps, and an inexact one costs accuracy only through the step-size
control. That is the form this model needs: it has no analytic Jacobian (an analytic one was
asked for; docs/numerics.md, "Jacobian", says why the compiled forward differences stayed),
and the Jacobian used here is the compiled Radau's, forward differences of the compiled kernel
in the model's scaled units (:func:`sphere_sim.model.dynamics.jacobian_kernel`).

A step solves four linear systems with one matrix and no Newton iteration. In the transformed
variables of Hairer & Wanner (*Solving ODEs II*, §IV.7, (7.4')), for this autonomous model::

    (I / (h gamma) - J) u_i = f(y + sum_{j<i} a_ij u_j) + sum_{j<i} (c_ij / h) u_j
    y_new = y + sum_i m_i u_i,   error = sum_i (m_i - m_hat_i) u_i

with ``a = alpha Gamma^-1``, ``c = diag(1 / gamma) - Gamma^-1``, ``m = b Gamma^-1`` from the
published ``alpha``, ``Gamma``, ``b``, ``b_hat`` (test/test_rosenbrock.py checks their order
conditions). The matrix is factored in the compiled Radau's reduced block-arrow form
(:func:`sphere_sim.integrate.newton_system.factor`, the kinematic states eliminated), once per
step size and Jacobian; its LU is kept while neither changes.

What it shares with the compiled Radau (:mod:`~sphere_sim.integrate.radau_compiled`), so that
the two are compared on the same terms:

* **Contact onset is never stepped over**: a step whose stage states or end state close a
  contact that was open at its start deeper than ``onset_depth_m`` is rejected and retried
  with the step that ends where the gap, interpolated linearly to the offending stage, reaches
  half that depth (:func:`_onset_fraction`, the same rule and the same shrink bounds).
* **The model's domain**: an electrode reaching the ground electrode ends the run.
* **No growth after a retry** (RADAU5's rule), a step held unchanged when it would grow by less
  than 20 % (so that the LU is reused), the step budget, the return to Python every
  ``CHUNK_STEPS`` accepted steps, and the counters (``radau_compiled.C_*``).

The Jacobian is kept from step to step (the W-method's licence) and computed afresh at the
step's start only after a rejection by the error test, a non-finite stage or a failed
factorisation made with an older one; a rejection with a fresh Jacobian shrinks the step.

Dense output: a cubic Hermite interpolant from ``y`` and ``f(y)`` at both ends of each
accepted step, whose error (O(h^4)) is of the method's own local error order, so samples
(t_eval) do not cut the steps. ``f(y_new)`` is the next step's first stage, so it costs
nothing; ROS34PW2 has no dense output of order 3 of its own.
"""

import math

import numba
import numpy as np

from sphere_sim.integrate import block_lu, newton_system
from sphere_sim.integrate import radau_compiled as rc
from sphere_sim.model import dynamics as dyn
from sphere_sim.model.gaps import contact_gaps, crossed_electrode, electrode_gaps, n_contacts

# --- ROS34PW2, Rang & Angermann (2005), Table 4.3: alpha_ij, gamma_ij, b_i, b_hat_i --------
GAMMA = 4.3586652150845900e-01  # the diagonal gamma_ii: L-stability with order 3
ALPHA = np.array([
    [0.0, 0.0, 0.0, 0.0],
    [8.7173304301691801e-01, 0.0, 0.0, 0.0],
    [8.4457060015369423e-01, -1.1299064236484185e-01, 0.0, 0.0],
    [0.0, 0.0, 1.0, 0.0]])
GAMMA_MATRIX = np.array([
    [GAMMA, 0.0, 0.0, 0.0],
    [-8.7173304301691801e-01, GAMMA, 0.0, 0.0],
    [-9.0338057013044082e-01, 5.4180672388095326e-02, GAMMA, 0.0],
    [2.4212380706095346e-01, -1.2232505839045147e+00, 5.4526025533510214e-01, GAMMA]])
B = np.array([2.4212380706095346e-01, -1.2232505839045147e+00, 1.5452602553351020e+00,
              4.3586652150845900e-01])  # order 3
B_HAT = np.array([3.7810903145819369e-01, -9.6042292212423178e-02, 0.5,
                  2.1793326075422950e-01])  # embedded, order 2
N_STAGES = 4
STAGE_C = ALPHA.sum(axis=1)  # stage abscissae: 0, 0.872, 0.732, 1
# The transformed coefficients (module docstring); strictly lower, rounding above cleared.
_GAMMA_INV = np.linalg.inv(GAMMA_MATRIX)
A_T = np.tril(ALPHA @ _GAMMA_INV, -1)
C_T = np.tril(np.diag(1.0 / np.diag(GAMMA_MATRIX)) - _GAMMA_INV, -1)
M = B @ _GAMMA_INV
M_ERR = (B - B_HAT) @ _GAMMA_INV  # the error estimate's weights
# Local error of the embedded pair is O(h^3): the step-size exponent is 1 / 3.
ERROR_EXPONENT = 1.0 / 3.0

SAFETY = 0.9  # step-size safety factor (scipy's and Radau's)
MIN_FACTOR = rc.MIN_FACTOR  # shrink at most 5x after an error rejection
MAX_FACTOR = rc.MAX_FACTOR  # grow at most 10x after an accepted step
# An accepted step's successor is held at its size unless it would grow by this or more, so
# that its LU is reused (Radau's rule).
HOLD_FACTOR = 1.2
# After a failed factorisation or a non-finite stage with a fresh Jacobian, halve the step.
FAILURE_SHRINK = 0.5

# The counters and status codes are the compiled Radau's (fast_segment reads both alike):
# C_NEWTON_FAILED counts stage sweeps lost to a non-finite stage or a failed factorisation.
STATUS_CHUNK = rc.STATUS_CHUNK
STATUS_DONE = rc.STATUS_DONE
STATUS_STEP_TOO_SMALL = rc.STATUS_STEP_TOO_SMALL
STATUS_STEP_BUDGET = rc.STATUS_STEP_BUDGET
STATUS_LEFT_DOMAIN = rc.STATUS_LEFT_DOMAIN
CHUNK_STEPS = rc.CHUNK_STEPS


@numba.njit(cache=True)
def _onset_fraction(gaps0, points, gaps_stage, n_gaps, p, flags, directions, onset_depth_m):
    """Fraction of the step after which the states ``points[i]`` (at the step fractions
    ``STAGE_C[i + 1]``: stages 2 to 4, then the end state at 1) first close a contact open at
    the step's start (gaps ``gaps0``) to half ``onset_depth_m``; 1.0 if none closes deeper than
    ``onset_depth_m``. As :func:`sphere_sim.integrate.radau_compiled._onset_fraction`."""
    worst = 1.0
    if not np.any(gaps0[:n_gaps] > 0.0):
        return worst
    for i in range(points.shape[0]):
        c = STAGE_C[i + 1] if i + 1 < N_STAGES else 1.0
        contact_gaps(points[i], p, flags, directions, gaps_stage)
        for k in range(n_gaps):
            g0 = gaps0[k]
            g1 = gaps_stage[k]
            if g0 > 0.0 and g1 < -onset_depth_m:
                worst = min(worst, c * (g0 + 0.5 * onset_depth_m) / (g0 - g1))
    return worst


@numba.njit(cache=True)
def _step_factor(h_abs, h_abs_old, error_norm, error_norm_old):
    """Gustafsson's predictive step-size factor (as Radau's) with the exponent 1/3."""
    if error_norm == 0.0:
        return MAX_FACTOR
    if error_norm_old < 0.0 or h_abs_old < 0.0:
        multiplier = 1.0
    else:
        multiplier = h_abs / h_abs_old * (error_norm_old / error_norm) ** ERROR_EXPONENT
    return min(1.0, multiplier) * error_norm ** -ERROR_EXPONENT


@numba.njit(cache=True, inline='always')
def _write_samples(t_eval, x_eval, i_eval, t_old, t_new, y_old, f_old, y_new, f_new):
    """Samples in (t_old, t_new] from the cubic Hermite interpolant of the step; returns the
    next sample's index."""
    h = t_new - t_old
    while i_eval < t_eval.size and t_eval[i_eval] <= t_new:
        s = (t_eval[i_eval] - t_old) / h
        h00 = (1.0 + 2.0 * s) * (1.0 - s) * (1.0 - s)
        h10 = s * (1.0 - s) * (1.0 - s)
        h01 = s * s * (3.0 - 2.0 * s)
        h11 = s * s * (s - 1.0)
        for j in range(y_old.size):
            x_eval[j, i_eval] = (h00 * y_old[j] + h10 * h * f_old[j] + h01 * y_new[j]
                                 + h11 * h * f_new[j])
        i_eval += 1
    return i_eval


# Exempt from C901: the accept/reject loop of a compiled integrator; its state (step size, LU
# and Jacobian validity, the controller's memory) lives in locals, as in radau_compiled.
@numba.njit(cache=True, nogil=True)
def integrate(t_start, t_end, x_start, u, arrays, rtol, atol, jac_scale, t_eval,  # noqa: C901
              x_eval, i_eval, h_first, max_step, max_steps, onset_depth_m, counters):
    """Integrate dx/dt = rhs(t, x, u) from ``t_start`` towards ``t_end`` with ROS34PW2.

    The arguments, returns and status codes are those of
    :func:`sphere_sim.integrate.radau_compiled.integrate`, without its Newton parameters
    (``jac_rate``, ``jac_central``: there is no Newton iteration, and the Jacobian is forward
    differences).

    Returns
    -------
    status : int
    t : float
    x : ndarray, shape (n,)
    h_next : float
    i_eval : int
    """
    p, flags, directions = arrays[0], arrays[1], arrays[2]
    n = x_start.size
    diag = np.empty(dyn.N_DIAG)
    t = t_start
    y = x_start.copy()
    f = np.empty(n)
    rc._rhs(t, y, u, arrays, f, diag, counters)
    rtol = max(rtol, 100.0 * rc.EPS)
    if h_first > 0.0:
        h_abs = min(h_first, t_end - t_start, max_step)
    else:
        h_abs = rc._initial_step(t, y, f, u, arrays, rtol, atol, t_end - t_start, max_step,
                                 diag, counters)

    layout = newton_system.model_layout(flags, n)
    pos, vel, red, pos_of = layout[0], layout[1], layout[2], layout[3]
    m = red.size
    dense_start, dense_end, dense_tail = block_lu.dense_structure(m)
    J = np.empty((n, n))
    J_RP = np.empty((m, pos.size))
    arrow = rc._new_jacobian(t, y, u, arrays, jac_scale, J, False, layout, J_RP, counters)
    current_jac = True
    LU = np.empty((m, m))
    piv = np.empty(m, dtype=np.int64)
    work = np.empty(m)
    have_lu = False
    h_lu = 0.0
    start_s, end_s, tail_s = dense_start, dense_end, dense_tail

    n_gaps = n_contacts(flags)
    check_onset = onset_depth_m > 0.0 and n_gaps > 0
    check_electrodes = flags[dyn.F_ELECTROSTATICS] != 0 and flags[dyn.F_N_BEAMS] > 0
    electrode_gap0 = np.zeros(flags[dyn.F_N_BEAMS])
    if check_electrodes:
        electrode_gaps(y, p, flags, electrode_gap0)
    gaps0 = np.empty(max(n_gaps, 1))
    gaps_stage = np.empty(max(n_gaps, 1))

    U = np.zeros((N_STAGES, n))
    points = np.zeros((N_STAGES, n))  # stages 2-4, then the end state: the onset rule's states
    rhs = np.empty(n)
    scale = np.empty(n)
    y_new = np.empty(n)
    f_new = np.empty(n)
    h_abs_old = -1.0
    error_norm_old = -1.0
    steps_here = 0

    while t < t_end:
        if steps_here >= max_steps:
            return STATUS_STEP_BUDGET, t, y, h_abs, i_eval
        if steps_here >= CHUNK_STEPS:
            return STATUS_CHUNK, t, y, h_abs, i_eval
        min_step = 10.0 * abs(np.nextafter(t, np.inf) - t)
        h_proposed = h_abs
        if h_abs > max_step or h_abs < min_step:
            h_abs = max_step if h_abs > max_step else min_step
            h_abs_old = -1.0
            error_norm_old = -1.0
        if check_onset:
            contact_gaps(y, p, flags, directions, gaps0)
        retried = False
        accepted = False
        error_norm = 0.0
        t_new = t
        h = h_abs
        while not accepted:
            if h_abs < min_step:
                return STATUS_STEP_TOO_SMALL, t, y, h_abs, i_eval
            t_new = min(t + h_abs, t_end)
            h = t_new - t
            h_abs = h
            g = 1.0 / (h * GAMMA)
            if not (have_lu and h == h_lu):
                ok, start_s, end_s, tail_s = newton_system.factor(
                    J, g, red, pos_of, LU, piv, arrow, layout[4], layout[5], layout[6],
                    dense_start, dense_end, dense_tail)
                counters[rc.C_NLU] += 1
                have_lu = ok
                h_lu = h
            finite = have_lu
            # The four stages: one factorisation, four solves, three new right-hand sides.
            for i in range(N_STAGES):
                if not finite:
                    break
                if i == 0:
                    for j in range(n):
                        rhs[j] = f[j]
                else:
                    for j in range(n):
                        acc = y[j]
                        for k in range(i):
                            acc += A_T[i, k] * U[k, j]
                        points[i - 1, j] = acc
                    rc._rhs(t + STAGE_C[i] * h, points[i - 1], u, arrays, rhs, diag, counters)
                    for j in range(n):
                        acc = rhs[j]
                        for k in range(i):
                            acc += C_T[i, k] / h * U[k, j]
                        rhs[j] = acc
                for j in range(n):
                    if not math.isfinite(rhs[j]):
                        finite = False
                newton_system.solve(LU, piv, J_RP, g, rhs, red, pos, vel, work, start_s,
                                    end_s, tail_s)
                for j in range(n):
                    U[i, j] = rhs[j]
            if not finite:
                # A failed factorisation or a non-finite stage: a fresh Jacobian first, then a
                # shorter step.
                counters[rc.C_NEWTON_FAILED] += 1
                counters[rc.C_REJECTED] += 1
                retried = True
                have_lu = False
                if current_jac:
                    h_abs *= FAILURE_SHRINK
                else:
                    arrow = rc._new_jacobian(t, y, u, arrays, jac_scale, J, False, layout,
                                             J_RP, counters)
                    current_jac = True
                continue
            for j in range(n):
                acc = y[j]
                err = 0.0
                for k in range(N_STAGES):
                    acc += M[k] * U[k, j]
                    err += M_ERR[k] * U[k, j]
                y_new[j] = acc
                points[N_STAGES - 1, j] = acc
                rhs[j] = err
                scale[j] = atol[j] + max(abs(y[j]), abs(acc)) * rtol

            # Contact onset: reject a step whose stages close an open contact too deeply.
            if check_onset:
                worst = _onset_fraction(gaps0, points, gaps_stage, n_gaps, p, flags,
                                        directions, onset_depth_m)
                if worst < 1.0:
                    h_abs *= min(rc.ONSET_SHRINK_MAX, max(rc.ONSET_SHRINK_MIN, worst))
                    counters[rc.C_REJECTED] += 1
                    counters[rc.C_ONSET_REJECTED] += 1
                    retried = True
                    continue

            error_norm = rc._rms(rhs, scale)
            if not math.isfinite(error_norm):
                error_norm = 1e10
            if error_norm > 1.0:
                factor = _step_factor(h_abs, h_abs_old, error_norm, error_norm_old)
                h_abs *= max(MIN_FACTOR, SAFETY * factor)
                counters[rc.C_REJECTED] += 1
                retried = True
                if not current_jac:
                    arrow = rc._new_jacobian(t, y, u, arrays, jac_scale, J, False, layout,
                                             J_RP, counters)
                    current_jac = True
                    have_lu = False
            else:
                accepted = True

        factor = min(MAX_FACTOR, SAFETY * _step_factor(h_abs, h_abs_old, error_norm,
                                                        error_norm_old))
        if retried:
            factor = min(1.0, factor)
        if factor < HOLD_FACTOR:
            factor = 1.0
        rc._rhs(t_new, y_new, u, arrays, f_new, diag, counters)
        h_abs_old = h_proposed
        error_norm_old = error_norm
        i_eval = _write_samples(t_eval, x_eval, i_eval, t, t_new, y, f, y_new, f_new)
        h_abs = h_abs * factor
        current_jac = False
        t = t_new
        for j in range(n):
            y[j] = y_new[j]
            f[j] = f_new[j]
        counters[rc.C_STEPS] += 1
        steps_here += 1
        if check_electrodes and crossed_electrode(y, electrode_gap0, p, flags) >= 0:
            return STATUS_LEFT_DOMAIN, t, y, h_abs, i_eval
    return STATUS_DONE, t, y, h_abs, i_eval
