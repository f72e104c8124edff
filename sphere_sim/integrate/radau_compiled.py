"""A compiled three-stage Radau IIA integrator for the assembled model (order 5, L-stable).

The method, its simplified Newton iteration, error estimate, step-size control and Jacobian
reuse follow scipy's ``scipy/integrate/_ivp/radau.py`` (Hairer & Wanner, *Solving Ordinary
Differential Equations II*, §IV.8), so that the two can be compared step for step. The main
difference is where it runs: the whole step loop, the right-hand side
(:func:`sphere_sim.model.dynamics.rhs_kernel`), the Jacobian and the LU factorisations are compiled
together by numba, so a step costs a few right-hand-side calls and two small LU solves and no
Python at all.

Additions (docs/numerics.md measures each):

* **Contact onset is never stepped over.** A contact that is open (gap > 0) at the start of a
  step must not be closed deeper than ``onset_depth_m`` at any stage of the step. If it is, the
  step is rejected and retried with the step that ends where the gap, interpolated linearly
  between the step start and the offending stage, reaches half that depth. Without this, an
  L-stable method at a loose tolerance can take one large step through an impact and damp the
  bounce away. The same rule is applied beforehand to the stages predicted by the previous
  step's collocation polynomial, so that Newton rarely starts across an impact.
* **The kinematic states are eliminated** from the Newton systems, which are then factored
  in block-arrow form (:mod:`~sphere_sim.integrate.newton_system`,
  :mod:`~sphere_sim.integrate.block_lu`); the real
  and the complex system are built, factored and solved side by side.
* **RADAU5's first-iterate test**: Newton may stop after one iteration when the previous
  solve contracted fast enough (Hairer's FACCON); scipy always takes two.
* **The model's domain**: a step after which an electrode has reached the ground electrode
  ends the run (``STATUS_LEFT_DOMAIN``) instead of letting the step collapse there.
* **RADAU5's rule after a retry**: a step that was accepted only after a retry (an error
  rejection, an onset rejection or a Newton failure) does not let the next one grow (Hairer's
  ``IF (REJECT) HNEW = MIN(HNEW, H)``); scipy lets it grow at once. On this model's kicks most
  retries are Newton failures where a bristle goes from sticking to slipping, and a step grown
  straight back into the next transition fails again (docs/numerics.md measures the rule).

The integrator returns to Python every ``CHUNK_STEPS`` accepted steps so that the caller can
enforce a wall-clock budget (numba has no clock).
"""

import math

import numba
import numpy as np

from sphere_sim.integrate import block_lu, newton_system
from sphere_sim.model import dynamics as dyn
from sphere_sim.model.gaps import (
    contact_gaps,
    crossed_electrode,
    electrode_gaps,
    n_contacts,
)

# --- Radau IIA (s = 3) coefficients, as in scipy's radau.py -----------------------------------
S6 = 6.0**0.5
C = np.array([(4.0 - S6) / 10.0, (4.0 + S6) / 10.0, 1.0])  # stage abscissae
E = np.array([-13.0 - 7.0 * S6, -13.0 + 7.0 * S6, -1.0]) / 3.0  # embedded error weights
# Eigenvalues of the inverse of the Butcher matrix: one real, one complex pair.
MU_REAL = 3.0 + 3.0 ** (2.0 / 3.0) - 3.0 ** (1.0 / 3.0)
MU_COMPLEX_RE = 3.0 + 0.5 * (3.0 ** (1.0 / 3.0) - 3.0 ** (2.0 / 3.0))
MU_COMPLEX_IM = -0.5 * (3.0 ** (5.0 / 6.0) + 3.0 ** (7.0 / 6.0))
# Transformation to the eigenbasis (T) and back (TI).
T = np.array([
    [0.09443876248897524, -0.14125529502095421, 0.03002919410514742],
    [0.25021312296533332, 0.20412935229379994, -0.38294211275726192],
    [1.0, 1.0, 0.0]])
TI = np.array([
    [4.17871859155190428, 0.32768282076106237, 0.52337644549944951],
    [-4.17871859155190428, -0.32768282076106237, 0.47662355450055044],
    [0.50287263494578682, -2.57192694985560522, 0.59603920482822492]])
# Dense output: y(t_old + x h) = y_old + Z^T P [x, x^2, x^3].
P = np.array([
    [13.0 / 3.0 + 7.0 * S6 / 3.0, -23.0 / 3.0 - 22.0 * S6 / 3.0, 10.0 / 3.0 + 5.0 * S6],
    [13.0 / 3.0 - 7.0 * S6 / 3.0, -23.0 / 3.0 + 22.0 * S6 / 3.0, 10.0 / 3.0 - 5.0 * S6],
    [1.0 / 3.0, -8.0 / 3.0, 10.0 / 3.0]])

NEWTON_MAXITER = 6  # simplified Newton iterations before the step is retried (scipy's value)
FACCON_RELAX = 0.8  # exponent that relaxes the last contraction factor towards 1 (RADAU5)
MIN_FACTOR = 0.2  # smallest step shrink after a rejected step (scipy's value)
MAX_FACTOR = 10.0  # largest step growth after an accepted step (scipy's value)
EPS = np.finfo(float).eps
CHUNK_STEPS = 2000  # accepted steps between returns to Python (wall-clock checks): ~20 ms
ONSET_SHRINK_MIN = 0.01  # an onset rejection shrinks the step by at most 100x per retry
ONSET_SHRINK_MAX = 0.9  # ... and by at least 10 %, so that the retry makes progress

# Status codes returned by :func:`integrate` (mapped to SolverStatus by sphere_sim.integrate.solve).
STATUS_CHUNK = 0  # CHUNK_STEPS accepted, call again
STATUS_DONE = 1  # reached t_end
STATUS_STEP_TOO_SMALL = -1  # the step fell below 10 ulp of t
STATUS_STEP_BUDGET = -2  # max_steps accepted steps taken without reaching t_end
STATUS_LEFT_DOMAIN = -3  # an electrode gap closed to <= 0 from > 0 (electrode_gaps)

# Indices into the int64 ``counters`` array.
C_STEPS = 0
C_REJECTED = 1
C_NFEV = 2
C_NJEV = 3
C_NLU = 4
C_ONSET_REJECTED = 5
C_NEWTON_FAILED = 6
C_ONSET_PREDICTED = 7
N_COUNTERS = 8


@numba.njit(cache=True)
def _rms(v, scale):
    acc = 0.0
    for i in range(v.size):
        r = v[i] / scale[i]
        acc += r * r
    return math.sqrt(acc / v.size)


@numba.njit(cache=True)
def _jacobian(t, x, u, p, flags, directions, rbf_cz, rbf_cphi, rbf_w, scale, J, central,
              red, pos_of, pos, J_RP, block_start, block_end, tail):
    """Jacobian into ``J`` (model order) and its position columns into ``J_RP``
    (:func:`sphere_sim.integrate.newton_system.position_columns`).

    Returns True if its reduced Newton matrix has the block-arrow structure
    (:func:`sphere_sim.integrate.newton_system.is_arrow`).
    """
    if central:
        dyn.jacobian_kernel_central(t, x, u, p, flags, directions, rbf_cz, rbf_cphi, rbf_w,
                                    scale, J)
    else:
        dyn.jacobian_kernel(t, x, u, p, flags, directions, rbf_cz, rbf_cphi, rbf_w, scale, J)
    newton_system.position_columns(J, red, pos, J_RP)
    return newton_system.is_arrow(J, red, pos_of, block_start, block_end, tail)


@numba.njit(cache=True)
def _onset_fraction(y, Z, gaps0, gaps_stage, stage, n_gaps, p, flags, directions,
                    onset_depth_m):
    """Fraction of the step after which the stages ``y + Z[i]`` first close a contact that is
    open at ``y`` (gaps ``gaps0``) to half ``onset_depth_m``; 1.0 if none closes deeper than
    ``onset_depth_m``. Gaps are interpolated linearly between the step start and each stage."""
    n = y.size
    worst = 1.0
    if not np.any(gaps0[:n_gaps] > 0.0):
        return worst
    for i in range(3):
        for j in range(n):
            stage[j] = y[j] + Z[i, j]
        contact_gaps(stage, p, flags, directions, gaps_stage)
        for c in range(n_gaps):
            g0 = gaps0[c]
            g1 = gaps_stage[c]
            if g0 > 0.0 and g1 < -onset_depth_m:
                worst = min(worst, C[i] * (g0 + 0.5 * onset_depth_m) / (g0 - g1))
    return worst


@numba.njit(cache=True)
def _predict_factor(h_abs, h_abs_old, error_norm, error_norm_old):
    """Gustafsson's predictive step-size factor (scipy's predict_factor)."""
    if error_norm_old < 0.0 or h_abs_old < 0.0 or error_norm == 0.0:
        multiplier = 1.0
    else:
        multiplier = h_abs / h_abs_old * (error_norm_old / error_norm) ** 0.25
    if error_norm == 0.0:
        return MAX_FACTOR
    return min(1.0, multiplier) * error_norm ** -0.25


@numba.njit(cache=True)
def _rhs(t, x, u, arrays, out, diag, counters):
    """The model's right-hand side into ``out``, counted."""
    p, flags, directions, rbf_cz, rbf_cphi, rbf_w = arrays
    dyn.rhs_kernel(t, x, u, p, flags, directions, rbf_cz, rbf_cphi, rbf_w, out, diag)
    counters[C_NFEV] += 1


@numba.njit(cache=True)
def _new_jacobian(t, x, u, arrays, jac_scale, J, central, layout, J_RP, counters):
    """:func:`_jacobian` on the bundled arrays, counted; True if block-arrow."""
    p, flags, directions, rbf_cz, rbf_cphi, rbf_w = arrays
    pos, red, pos_of, arrow_start, arrow_end, arrow_tail = (layout[0], layout[2], layout[3],
                                                            layout[4], layout[5], layout[6])
    counters[C_NJEV] += 1
    return _jacobian(t, x, u, p, flags, directions, rbf_cz, rbf_cphi, rbf_w, jac_scale, J,
                     central, red, pos_of, pos, J_RP, arrow_start, arrow_end, arrow_tail)


@numba.njit(cache=True)
def _initial_step(t, y, f, u, arrays, rtol, atol, interval, max_step, diag, counters):
    """First step as scipy's ``select_initial_step`` with error-estimator order 3."""
    n = y.size
    sc = np.empty(n)
    for i in range(n):
        sc[i] = atol[i] + abs(y[i]) * rtol
    d0 = _rms(y, sc)
    d1 = _rms(f, sc)
    h0 = 1e-6 if (d0 < 1e-5 or d1 < 1e-5) else 0.01 * d0 / d1
    h0 = min(h0, interval)
    y1 = y + h0 * f
    f1 = np.empty(n)
    _rhs(t + h0, y1, u, arrays, f1, diag, counters)
    d2 = _rms(f1 - f, sc) / h0
    tiny = d1 <= 1e-15 and d2 <= 1e-15
    h1 = max(1e-6, h0 * 1e-3) if tiny else (0.01 / max(d1, d2)) ** 0.25
    return min(100.0 * h0, h1, interval, max_step)


@numba.njit(cache=True, inline='always')
def _extrapolate(Z, y, t, h, have_dense, t_old, h_dense, y_old, Q):
    """Newton's starting guess: the previous step's collocation polynomial (from ``t_old``
    over ``h_dense``) at the new stage times, or zero without one (as scipy's Radau)."""
    n = y.size
    for i in range(3):
        for j in range(n):
            if have_dense:
                xs = (t + h * C[i] - t_old) / h_dense
                Z[i, j] = (y_old[j] + Q[j, 0] * xs + Q[j, 1] * xs * xs
                           + Q[j, 2] * xs * xs * xs) - y[j]
            else:
                Z[i, j] = 0.0


@numba.njit(cache=True, inline='always')
def _error_norm(t, y, f, u, arrays, Z, h, h_lu, rejected, atol, rtol, lu, layout,
                structure_r, y_new, err, scale, stage, ZE, f_new, diag, counters):
    """The embedded error estimate of the step (scipy's), filtered through the real Newton
    matrix; after a rejection an estimate above 1 is refined once, as scipy does. Fills
    ``y_new`` with the step's end state."""
    LU_real, piv_real, J_RP, work_real = lu[0], lu[1], lu[4], lu[5]
    pos, vel, red = layout[0], layout[1], layout[2]
    start_r, end_r, tail_r = structure_r
    n = y.size
    for j in range(n):
        y_new[j] = y[j] + Z[2, j]
        ZE[j] = (Z[0, j] * E[0] + Z[1, j] * E[1] + Z[2, j] * E[2]) / h
        err[j] = f[j] + ZE[j]
        scale[j] = atol[j] + max(abs(y[j]), abs(y_new[j])) * rtol
    newton_system.solve(LU_real, piv_real, J_RP, MU_REAL / h_lu, err, red, pos, vel,
                        work_real, start_r, end_r, tail_r)
    error_norm = _rms(err, scale)
    if rejected and error_norm > 1.0:
        for j in range(n):
            stage[j] = y[j] + err[j]
        _rhs(t, stage, u, arrays, f_new, diag, counters)
        for j in range(n):
            err[j] = f_new[j] + ZE[j]
        newton_system.solve(LU_real, piv_real, J_RP, MU_REAL / h_lu, err, red, pos, vel,
                            work_real, start_r, end_r, tail_r)
        error_norm = _rms(err, scale)
    if not math.isfinite(error_norm):
        error_norm = 1e10
    return error_norm


@numba.njit(cache=True, inline='always')
def _dense_output(y, Z, y_old, Q):
    """Keep the accepted step's collocation polynomial: ``y_old`` and its coefficients ``Q``."""
    for j in range(y.size):
        y_old[j] = y[j]
        for m in range(3):
            Q[j, m] = Z[0, j] * P[0, m] + Z[1, j] * P[1, m] + Z[2, j] * P[2, m]


@numba.njit(cache=True, inline='always')
def _write_samples(t_eval, x_eval, i_eval, t_new, t_old, h_dense, y_old, Q):
    """Samples up to ``t_new`` from the dense output; returns the next sample's index."""
    while i_eval < t_eval.size and t_eval[i_eval] <= t_new:
        xs = (t_eval[i_eval] - t_old) / h_dense
        for j in range(y_old.size):
            x_eval[j, i_eval] = (y_old[j] + Q[j, 0] * xs + Q[j, 1] * xs * xs
                                 + Q[j, 2] * xs * xs * xs)
        i_eval += 1
    return i_eval


# Exempt from C901: the accept/reject loop of a compiled integrator, with the simplified
# Newton iteration inside it. Its state (step size, LU validity, Jacobian age, dense output,
# Newton's contraction) lives in locals; the initial step, the starting guess, the error
# estimate and the dense output are functions above (the per-step ones inlined by numba). The
# Newton iteration was a function too: that cost 5-6 % of every kick (median over the three
# work-precision scenes at three tolerances), because numba counts references to each array
# handed to a call, and the iteration needs fifteen of them. It stays here. It releases the
# GIL (nogil): the live twin publishes one sample on another thread while it integrates the next.
@numba.njit(cache=True, nogil=True)
def integrate(t_start, t_end, x_start, u, arrays, rtol, atol, jac_scale, t_eval,  # noqa: C901
              x_eval, i_eval, h_first, max_step, max_steps, onset_depth_m, jac_rate,
              jac_central, counters):
    """Integrate dx/dt = rhs(t, x, u) from ``t_start`` towards ``t_end`` with Radau IIA.

    The step loop of scipy's ``Radau._step_impl``: the initial step (:func:`_initial_step`),
    the starting guess (:func:`_extrapolate`), the simplified Newton on the collocation
    system, the error estimate (:func:`_error_norm`), the dense output (:func:`_dense_output`,
    :func:`_write_samples`), plus the contact-onset and electrode checks of the module
    docstring.

    Parameters
    ----------
    t_start, t_end : float
        Interval (s), ``t_end > t_start``; ``u`` is constant on it.
    x_start : ndarray, shape (n,)
    u : ndarray, shape (n_beams,)
        Beam voltages (V).
    arrays : tuple
        The packed model, ``Model.kernel_arrays``: (p, flags, directions, rbf_cz, rbf_cphi,
        rbf_w).
    rtol : float
    atol : ndarray, shape (n,)
    jac_scale : ndarray, shape (n,)
        Characteristic state magnitudes for the Jacobian's difference steps.
    t_eval : ndarray, shape (m,)
        Increasing sample times (s); those in (t_start, t_end] are filled from the dense output.
    x_eval : ndarray, shape (n, m)
        Output samples.
    i_eval : int
        Index of the first sample not yet written.
    h_first : float
        First step (s); <= 0 selects it as scipy does.
    max_step : float
        Largest step (s).
    max_steps : int
        Accepted steps allowed in this call before STATUS_STEP_BUDGET (chunks count apart).
    onset_depth_m : float
        Deepest allowed closure, within one step, of a contact open at the step's start (m);
        <= 0 disables the check.
    jac_rate : float
        Newton contraction rate above which the Jacobian is recomputed after a step that took
        more than two iterations (Hairer's THET; scipy uses 1e-3).
    jac_central : bool
        Central instead of forward differences for the Jacobian (twice the cost).
    counters : ndarray of int64, shape (N_COUNTERS,)
        Incremented in place.

    Returns
    -------
    status : int
        One of the STATUS_* codes.
    t : float
        Time reached (s).
    x : ndarray, shape (n,)
        State at ``t``.
    h_next : float
        Step proposed for the next call (s).
    i_eval : int
        Index of the first sample not yet written.
    """
    p, flags, directions, rbf_cz, rbf_cphi, rbf_w = arrays
    n = x_start.size
    diag = np.empty(dyn.N_DIAG)
    t = t_start
    y = x_start.copy()
    f = np.empty(n)
    dyn.rhs_kernel(t, y, u, p, flags, directions, rbf_cz, rbf_cphi, rbf_w, f, diag)
    counters[C_NFEV] += 1
    rtol = max(rtol, 100.0 * EPS)
    newton_tol = max(10.0 * EPS / rtol, min(0.03, rtol**0.5))
    if h_first > 0.0:
        h_abs = min(h_first, t_end - t_start, max_step)
    else:
        h_abs = _initial_step(t, y, f, u, arrays, rtol, atol, t_end - t_start, max_step, diag,
                              counters)

    # Newton systems without the kinematic states (sphere_sim.integrate.newton_system),
    # block-arrow where that succeeds, dense otherwise.
    layout = newton_system.model_layout(flags, n)
    m = layout[2].size
    dense_structure = block_lu.dense_structure(m)
    J = np.empty((n, n))
    J_RP = np.empty((m, layout[0].size))
    arrow = _new_jacobian(t, y, u, arrays, jac_scale, J, jac_central, layout, J_RP, counters)
    current_jac = True
    arrow_structure = (layout[4], layout[5], layout[6])
    structures = (arrow_structure, arrow_structure)
    lu = (np.empty((m, m)), np.empty(m, dtype=np.int64), np.empty((m, m), dtype=np.complex128),
          np.empty(m, dtype=np.int64), J_RP, np.empty(m), np.empty(m, dtype=np.complex128))
    have_lu = False
    h_lu = 0.0
    h_abs_old = -1.0
    error_norm_old = -1.0
    y_old = y.copy()
    Q = np.zeros((n, 3))
    have_dense = False
    t_old = t
    h_dense = 1.0

    n_gaps = n_contacts(flags)
    check_onset = onset_depth_m > 0.0 and n_gaps > 0
    check_electrodes = flags[dyn.F_ELECTROSTATICS] != 0 and flags[dyn.F_N_BEAMS] > 0
    electrode_gap0 = np.zeros(flags[dyn.F_N_BEAMS])
    if check_electrodes:
        electrode_gaps(y, p, flags, electrode_gap0)
    gaps0 = np.empty(max(n_gaps, 1))
    gaps_stage = np.empty(max(n_gaps, 1))

    Z = np.zeros((3, n))
    stage = np.empty(n)
    W = np.zeros((3, n))
    F = np.zeros((3, n))
    dW = np.zeros((3, n))
    f_real = np.empty(n)
    f_cplx = np.empty(n, dtype=np.complex128)
    mu_c = complex(MU_COMPLEX_RE, MU_COMPLEX_IM)
    pos, vel, red = layout[0], layout[1], layout[2]
    LU_real, piv_real, LU_complex, piv_complex = lu[0], lu[1], lu[2], lu[3]
    work_real, work_complex = lu[5], lu[6]
    scale = np.empty(n)
    err = np.empty(n)
    ZE = np.empty(n)
    y_new = np.empty(n)
    f_new = np.empty(n)
    steps_here = 0
    faccon = 1.0

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
        rejected = False
        retried = False  # any retry of this step, Newton failures included (RADAU5's REJECT)
        accepted = False
        n_iter = 0
        rate = 0.0
        error_norm = 0.0
        safety = 0.9
        t_new = t
        h = h_abs
        while not accepted:
            if h_abs < min_step:
                return STATUS_STEP_TOO_SMALL, t, y, h_abs, i_eval
            t_new = min(t + h_abs, t_end)
            h = t_new - t
            h_abs = h
            if have_lu and h != h_lu:
                have_lu = False
            _extrapolate(Z, y, t, h, have_dense, t_old, h_dense, y_old, Q)
            # Bound the step by the predicted time to contact: Newton with a Jacobian taken
            # while a contact is open diverges when the stages close it, and each divergence
            # costs up to NEWTON_MAXITER stage sweeps and a fresh Jacobian before h is halved.
            if check_onset and have_dense:
                worst = _onset_fraction(y, Z, gaps0, gaps_stage, stage, n_gaps, p, flags,
                                        directions, onset_depth_m)
                if worst < 1.0:
                    h_abs *= min(ONSET_SHRINK_MAX, max(ONSET_SHRINK_MIN, worst))
                    counters[C_ONSET_PREDICTED] += 1
                    continue
            for j in range(n):
                scale[j] = atol[j] + abs(y[j]) * rtol
            converged = False
            while not converged:
                if not have_lu:
                    ok, structure_r, structure_c = newton_system.factor_pair(
                        J, MU_REAL / h, complex(MU_COMPLEX_RE, MU_COMPLEX_IM) / h, layout[2],
                        layout[3], lu[0], lu[1], lu[2], lu[3], arrow, layout[4], layout[5],
                        layout[6], dense_structure[0], dense_structure[1],
                        dense_structure[2])
                    counters[C_NLU] += 2
                    if not ok:
                        break
                    structures = (structure_r, structure_c)
                    have_lu = True
                    h_lu = h
                # Simplified Newton on the collocation system (scipy's
                # solve_collocation_system); why it is not a function: above integrate.
                mr = MU_REAL / h
                mc = mu_c / h
                for i in range(3):
                    for j in range(n):
                        W[i, j] = TI[i, 0] * Z[0, j] + TI[i, 1] * Z[1, j] + TI[i, 2] * Z[2, j]
                dW_norm_old = -1.0
                rate = -1.0
                # Hairer's RADAU5: the first iteration is judged by the contraction of the
                # previous Newton solve, relaxed towards 1, instead of always taking a second.
                faccon = max(faccon, EPS) ** FACCON_RELAX
                converged = False
                k = 0
                for k in range(NEWTON_MAXITER):
                    finite = True
                    for i in range(3):
                        for j in range(n):
                            stage[j] = y[j] + Z[i, j]
                        dyn.rhs_kernel(t + C[i] * h, stage, u, p, flags, directions, rbf_cz,
                                       rbf_cphi, rbf_w, F[i], diag)
                        counters[C_NFEV] += 1
                        for j in range(n):
                            if not math.isfinite(F[i, j]):
                                finite = False
                    if not finite:
                        break
                    for j in range(n):
                        f_real[j] = (TI[0, 0] * F[0, j] + TI[0, 1] * F[1, j]
                                     + TI[0, 2] * F[2, j] - mr * W[0, j])
                        fc_re = TI[1, 0] * F[0, j] + TI[1, 1] * F[1, j] + TI[1, 2] * F[2, j]
                        fc_im = TI[2, 0] * F[0, j] + TI[2, 1] * F[1, j] + TI[2, 2] * F[2, j]
                        f_cplx[j] = complex(fc_re, fc_im) - mc * complex(W[1, j], W[2, j])
                    newton_system.solve_pair(LU_real, piv_real, LU_complex, piv_complex, J_RP,
                                             mr, mc, f_real, f_cplx, red, pos, vel, work_real,
                                             work_complex, structures[0], structures[1])
                    for j in range(n):
                        dW[0, j] = f_real[j]
                        dW[1, j] = f_cplx[j].real
                        dW[2, j] = f_cplx[j].imag
                    acc = 0.0
                    for j in range(n):
                        for i in range(3):
                            r = dW[i, j] / scale[j]
                            acc += r * r
                    dW_norm = math.sqrt(acc / (3 * n))
                    if dW_norm_old >= 0.0:
                        rate = dW_norm / dW_norm_old
                    if rate >= 0.0 and (rate >= 1.0 or rate ** (NEWTON_MAXITER - k)
                                        / (1.0 - rate) * dW_norm > newton_tol):
                        break
                    for i in range(3):
                        for j in range(n):
                            W[i, j] += dW[i, j]
                    for i in range(3):
                        for j in range(n):
                            Z[i, j] = T[i, 0] * W[0, j] + T[i, 1] * W[1, j] + T[i, 2] * W[2, j]
                    if rate >= 0.0:
                        faccon = rate / (1.0 - rate)
                    if dW_norm == 0.0 or faccon * dW_norm < newton_tol:
                        converged = True
                        break
                    dW_norm_old = dW_norm
                n_iter = k + 1
                if not converged:
                    if current_jac:
                        break
                    arrow = _new_jacobian(t, y, u, arrays, jac_scale, J, jac_central, layout,
                                          J_RP, counters)
                    current_jac = True
                    have_lu = False
            if not converged:
                h_abs *= 0.5
                retried = True
                have_lu = False
                counters[C_REJECTED] += 1
                counters[C_NEWTON_FAILED] += 1
                continue

            # Contact onset: reject a step that closes an open contact too deeply.
            if check_onset:
                worst = _onset_fraction(y, Z, gaps0, gaps_stage, stage, n_gaps, p, flags,
                                        directions, onset_depth_m)
                if worst < 1.0:
                    h_abs *= min(ONSET_SHRINK_MAX, max(ONSET_SHRINK_MIN, worst))
                    have_lu = False
                    have_dense = False
                    counters[C_REJECTED] += 1
                    counters[C_ONSET_REJECTED] += 1
                    rejected = True
                    continue

            error_norm = _error_norm(t, y, f, u, arrays, Z, h, h_lu, rejected, atol, rtol, lu,
                                     layout, structures[0], y_new, err, scale, stage, ZE,
                                     f_new, diag, counters)
            safety = 0.9 * (2 * NEWTON_MAXITER + 1) / (2 * NEWTON_MAXITER + n_iter)
            if error_norm > 1.0:
                factor = _predict_factor(h_abs, h_abs_old, error_norm, error_norm_old)
                h_abs *= max(MIN_FACTOR, safety * factor)
                have_lu = False
                rejected = True
                counters[C_REJECTED] += 1
            else:
                accepted = True

        recompute_jac = n_iter > 2 and rate > jac_rate
        factor = _predict_factor(h_abs, h_abs_old, error_norm, error_norm_old)
        factor = min(MAX_FACTOR, safety * factor)
        if retried or rejected:
            factor = min(1.0, factor)
        if not recompute_jac and factor < 1.2:
            factor = 1.0
        else:
            have_lu = False
        dyn.rhs_kernel(t_new, y_new, u, p, flags, directions, rbf_cz, rbf_cphi, rbf_w, f_new,
                       diag)
        counters[C_NFEV] += 1
        if recompute_jac:
            arrow = _new_jacobian(t_new, y_new, u, arrays, jac_scale, J, jac_central, layout,
                                  J_RP, counters)
        current_jac = recompute_jac
        h_abs_old = h_proposed
        error_norm_old = error_norm
        _dense_output(y, Z, y_old, Q)
        have_dense, t_old, h_dense = True, t, h
        i_eval = _write_samples(t_eval, x_eval, i_eval, t_new, t_old, h_dense, y_old, Q)
        h_abs = h_abs * factor
        t = t_new
        for j in range(n):
            y[j] = y_new[j]
            f[j] = f_new[j]
        counters[C_STEPS] += 1
        steps_here += 1
        if check_electrodes and crossed_electrode(y, electrode_gap0, p, flags) >= 0:
            return STATUS_LEFT_DOMAIN, t, y, h_abs, i_eval
    return STATUS_DONE, t, y, h_abs, i_eval
