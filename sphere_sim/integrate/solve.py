"""Time integration of an assembled model through a voltage programme.

Two entry points share one implementation:

``solve(model, t_span, rtol, atol, method)``
    The small interface of the benchmarks: an assembled model (started from its scene's
    initial state unless told otherwise), a time span, tolerances and a method name.
``simulate(model, x0, t_end_s, programme, ...)``
    The older call used by runs, kicks, pull-in and the lookup table; same engine.

Methods (docs/numerics.md compares them):

========  ====================================================================================
fast      the compiled Radau IIA of :mod:`~sphere_sim.integrate.radau_compiled` (the default)
Radau     scipy's Radau IIA, BDF, LSODA and the explicit DOP853, stepped one step at a time
BDF       from Python on the same compiled right-hand side and Jacobian
LSODA
DOP853
odeint    the same Fortran LSODA through ``scipy.integrate.odeint``: its step loop runs in
          Fortran and calls back only for the right-hand side and the Jacobian
CVODE     SUNDIALS CVODE (BDF, dense direct solver) through scikit-sundae
========  ====================================================================================

Every method restarts at each voltage edge of the programme, so no step straddles a jump of
the input, and none steps over a contact onset: a contact open at the start of a step may not
close deeper than ``onset_depth_m`` within it. The compiled method checks every stage of every
step and rejects such a step. The library methods check the end of each step (a check of
interior points on every step would cost scipy more than its own stepping) and, when it is
closed too deep, stop at the onset, found by root finding on the dense output, and restart
there; CVODE does the same with its own root finding. odeint returns only at the times it is
asked for, so it is asked for a grid of check points (ODEINT_CHECK_PERIOD_S) besides the
samples: a contact open at one check point may not close deeper than ``onset_depth_m`` by
the next; when one does, the interval is integrated again on finer grids down to the onset,
and odeint restarts there.
Each run is bounded by a wall-clock and a step budget and ends either with a
:class:`Trajectory` or with a :class:`SolverError` that says where and why it stopped.
"""

import dataclasses
import enum
import itertools
import math
import time
import warnings

import numpy as np
import scipy.integrate
from scipy.optimize import brentq

from sphere_sim.model import gaps as gap_kernels
from sphere_sim.model.initial_state import initial_state
from sphere_sim.model.programme import PulseProgramme, VoltageSchedule
from sphere_sim.model.scaling import state_scale

METHODS = ('fast', 'Radau', 'BDF', 'LSODA', 'odeint', 'DOP853', 'CVODE')
SCIPY_METHODS = ('Radau', 'BDF', 'LSODA', 'odeint', 'DOP853')
IMPLICIT_METHODS = ('Radau', 'BDF', 'LSODA')
DEFAULT_METHOD = 'fast'
# rtol of solve(): the final surface normal of the optimised kick is then within about 1e-8 rad
# of the converged value (bench/results/work_precision.md), far below what a kick resolves.
DEFAULT_RTOL = 1e-6
# A run of the ~100 ms scenes takes well under a second; ten minutes means it is stuck.
DEFAULT_MAX_WALL_S = 600.0
# Accepted steps per run: the stiffest shipped scenes take ~1e4 steps per simulated 100 ms at
# rtol 1e-8, so 2e7 allows 10 s of simulated time at any tolerance before calling it a stall.
DEFAULT_MAX_STEPS = 20_000_000
# Deepest closure of an open contact within one step, as a fraction of the contact law's
# transition depth 2 C / k_c (100 nm with Table A1): 2 nm, where the contact force is still
# 4e-4 C and starting the contact that late adds ~1e-15 J of elastic energy.
ONSET_DEPTH_FRACTION = 0.02
# Points of a flagged scipy step at which its dense output is searched for the first deep
# closure, which then brackets the root.
ONSET_CHECK_POINTS = np.array([0.25, 0.5, 0.75, 1.0])
# The library methods check the model's domain (check_domain) every this many steps: a crossing
# stalls them for thousands of steps, and a check on every step cost LSODA 3-5 % of its time,
# which would flatter the compiled method in the benchmarks.
DOMAIN_CHECK_STEPS = 32
# odeint's onset test runs on check points this far apart (and at the samples): it returns
# only at the times it is asked for. LSODA interpolates to them instead of stepping to them;
# each costs 55 ns to interpolate and store and 140 ns for the compiled gap test, about 6 ms
# for the 30 000 points of the 60 ms kick, 4 % of odeint's time there (docs/numerics.md).
ODEINT_CHECK_PERIOD_S = 2e-6
# Check points per odeint call (10 ms of simulated time): the call's output holds them all,
# and the next call restarts LSODA at order 1. Calls of 1 ms took the diagonal kick 19 % more
# steps at rtol 1e-3, calls of 5 ms none more; an onset throws away the rest of its call.
ODEINT_CHUNK_POINTS = 5000
# An onset between two check points is found by integrating the interval again on a grid
# of this many points, then the subinterval where the gap jumped past the allowed depth, and
# so on: each level narrows the time by this factor (2 us to 8 ns in two levels).
ODEINT_LOCATE_POINTS = 16
ODEINT_LOCATE_LEVELS = 8
# A call whose contact gaps after a closure agree with a fresh start's within this fraction of
# the allowed depth resolved the onset. Measured: 0.02-0.26 nm on the kicks at rtol 1e-3, up
# to 1.2 nm for the sphere dropped on the tips at 1e-2. Restarting at every closure instead
# cost the drop 2.7 times the steps for a landing depth 5.5 % off rather than 7.8 %.
ODEINT_ONSET_AGREEMENT = 1.0
# LSODA's mxstep is a 32-bit count of steps per output interval.
ODEINT_MAX_MXSTEP = 2**31 - 1
ODEINT_SUCCESS = 'Integration successful.'
# The model's Jacobian has a row per equation (d f_i / d x_j at [i, j]), which odeint reads
# with col_deriv=False; True would read it transposed.
ODEINT_COL_DERIV = False
# Newton contraction rate above which the compiled Radau refreshes its Jacobian: Hairer's
# recommendation (THET = 0.1) when a Jacobian costs many right-hand sides; ours costs n + 1.
FAST_JACOBIAN_RATE = 0.1
# Forward differences of the compiled kernel for the compiled Radau's Jacobian: central ones
# are ~1e4 times more accurate but change neither the steps nor the result, and cost twice as
# much (docs/numerics.md, "Jacobian").
FAST_JACOBIAN_CENTRAL = False


class SolverStatus(enum.Enum):
    SUCCESS = 'success'
    FAILED = 'failed'
    BUDGET_EXCEEDED = 'budget_exceeded'
    STEP_TOO_SMALL = 'step_too_small'
    LEFT_MODEL_DOMAIN = 'left_model_domain'


class SolverError(RuntimeError):
    """The integration could not proceed; carries the time and state where it stopped."""

    def __init__(self, message, t_s=None, state=None, status=SolverStatus.FAILED):
        super().__init__(message)
        self.t_s = t_s
        self.state = state
        self.status = status


@dataclasses.dataclass
class SolverStats:
    """Work done by one run.

    ``nfev`` counts right-hand-side calls made by the method itself; each Jacobian (``njev``)
    costs another ``n_states + 1`` compiled calls on top. ``n_steps`` and ``n_rejected`` are
    None where the library does not expose them (scipy does not count rejections; CVODE
    through scikit-sundae reports neither). Only the compiled method counts
    ``n_newton_failed`` (attempts whose Newton iteration did not converge) and
    ``n_onset_bounded`` (steps shortened beforehand to a predicted contact onset); they are
    None for the others. ``n_onset_restarts`` counts steps rejected or restarted at an onset.
    """

    nfev: int = 0
    njev: int = 0
    nlu: int = 0
    n_segments: int = 0
    wall_time_s: float = 0.0
    n_steps: int | None = 0
    n_rejected: int | None = 0
    n_onset_restarts: int = 0
    n_newton_failed: int | None = 0
    n_onset_bounded: int | None = 0
    method: str = ''


@dataclasses.dataclass
class Trajectory:
    """Sampled solution.

    Attributes
    ----------
    t : ndarray, shape (n_times,)
        Times in s.
    x : ndarray, shape (n_states, n_times)
    u : ndarray, shape (n_beams, n_times)
        Voltages applied (V) on the segment each sample belongs to.
    """

    model: object
    t: np.ndarray
    x: np.ndarray
    u: np.ndarray
    status: SolverStatus
    stats: SolverStats
    message: str = ''

    @property
    def final_state(self):
        return self.x[:, -1]

    def surface_normal(self):
        """Surface normal over time, shape (3, n_times)."""
        return self.model.surface_normal(self.x)


def segment_times(programme, t_start_s, t_end_s):
    """Boundaries of the constant-voltage segments inside [t_start_s, t_end_s]."""
    inner = [t for t in programme.edges() if t_start_s < t < t_end_s]
    return [t_start_s, *inner, t_end_s]


def default_onset_depth_m(model):
    """ONSET_DEPTH_FRACTION of the contact's transition depth 2 C / k_c (m)."""
    c = model.params.contact
    return ONSET_DEPTH_FRACTION * 2.0 * c.transition_force_n / c.stiffness_n_per_m


def check_domain(model, t, x, u, gaps_start):
    """Raise a LEFT_MODEL_DOMAIN error if an electrode has reached the ground electrode.

    That happens when the contact law is too soft to hold a beam against its electrostatic
    pull (e.g. k_c / 100 at 80 V); the parallel-plate force is then unbounded, and a solver
    would otherwise stall in ever smaller steps. Only a crossing since the electrode gaps
    ``gaps_start`` (:meth:`Model.electrode_gaps`) counts. One compiled call when nothing crossed.
    """
    k = gap_kernels.crossed_electrode(x, gaps_start, model.p, model.flags)
    if k >= 0:
        gap = model.electrode_gaps(x)[k]
        raise SolverError(
            f'beam {model.beams[k]} left the model at t = {t} s: its electrode reached the ground '
            f'electrode (gap {gap * 1e6:.3g} um) at {u[k]:g} V; the contact law '
            f'(k_c = {model.params.contact.stiffness_n_per_m:g} N/m) cannot hold it there',
            t, np.array(x), SolverStatus.LEFT_MODEL_DOMAIN)


class _Budget:
    """Wall-clock deadline and accepted-step allowance shared by all segments of a run."""

    def __init__(self, max_wall_s, max_steps):
        self.started = time.perf_counter()
        self.max_wall_s = max_wall_s
        self.deadline = None if max_wall_s is None else self.started + max_wall_s
        self.max_steps = max_steps
        self.steps = 0

    def check(self, t, x):
        if self.deadline is not None and time.perf_counter() > self.deadline:
            raise SolverError(f'wall-clock budget of {self.max_wall_s} s exceeded at t = {t} s',
                              t, np.array(x), SolverStatus.BUDGET_EXCEEDED)
        if self.steps > self.max_steps:
            raise SolverError(f'step budget of {self.max_steps} steps exceeded at t = {t} s',
                              t, np.array(x), SolverStatus.BUDGET_EXCEEDED)


def _segment_fast(model, x, t0, t1, u, rtol, atol, t_eval, onset_depth_m, budget, stats):
    """Integrate one constant-voltage segment with the compiled Radau IIA."""
    from sphere_sim.integrate import radau_compiled as rc
    counters = np.zeros(rc.N_COUNTERS, dtype=np.int64)
    x_eval = np.empty((model.n_states, t_eval.size))
    jac_scale = state_scale(model)
    t, h, i_eval = t0, -1.0, 0
    x = np.ascontiguousarray(x, dtype=float)
    status = rc.STATUS_CHUNK
    while status == rc.STATUS_CHUNK:
        budget.check(t, x)
        steps_before = int(counters[rc.C_STEPS])
        x_chunk = x
        status, t, x, h, i_eval = rc.integrate(
            t, t1, x, u, model.kernel_arrays, float(rtol), atol, jac_scale, t_eval, x_eval,
            i_eval, h, np.inf, max(1, budget.max_steps - budget.steps), onset_depth_m,
            FAST_JACOBIAN_RATE, FAST_JACOBIAN_CENTRAL, counters)
        budget.steps += int(counters[rc.C_STEPS]) - steps_before
        if status == rc.STATUS_STEP_BUDGET:
            budget.steps = max(budget.steps, budget.max_steps + 1)
    stats.nfev += int(counters[rc.C_NFEV])
    stats.njev += int(counters[rc.C_NJEV])
    stats.nlu += int(counters[rc.C_NLU])
    stats.n_steps += int(counters[rc.C_STEPS])
    stats.n_rejected += int(counters[rc.C_REJECTED])
    stats.n_onset_restarts += int(counters[rc.C_ONSET_REJECTED])
    stats.n_newton_failed += int(counters[rc.C_NEWTON_FAILED])
    stats.n_onset_bounded += int(counters[rc.C_ONSET_PREDICTED])
    budget.check(t, x)
    if status == rc.STATUS_LEFT_DOMAIN:
        check_domain(model, t, x, u, model.electrode_gaps(x_chunk))
    if status == rc.STATUS_STEP_TOO_SMALL or not np.all(np.isfinite(x)):
        raise SolverError(f'fast: step size fell below 10 ulp of t at t = {t} s (h = {h:.3g} s)',
                          t, x, SolverStatus.STEP_TOO_SMALL)
    return x, x_eval[:, :i_eval]


def _scipy_solver(method, fun, jac, t0, x, t1, rtol, atol, first_step=None):
    cls = getattr(scipy.integrate, method)
    options = {'rtol': rtol, 'atol': atol}
    if method in IMPLICIT_METHODS:
        options['jac'] = jac
    if first_step is not None:
        options['first_step'] = first_step
    return cls(fun, t0, x, t1, **options)


def _first_onset(model, dense, t_a, t_b, open_mask, onset_depth_m):
    """Time in (t_a, t_b] at which a contact open at ``t_a`` has closed by half the allowed
    depth, found on the step's dense output (called when the step's end shows it closed
    deeper than the allowed depth)."""
    t_hit = None
    for frac in ONSET_CHECK_POINTS:
        t = t_a + frac * (t_b - t_a)
        gaps = model.contact_gaps(dense(t))
        deep = open_mask & (gaps < -onset_depth_m)
        if np.any(deep):
            t_hit = t
            break
    if t_hit is None:
        return None

    def shallowest(t):
        return float(np.min(model.contact_gaps(dense(t))[open_mask])) + 0.5 * onset_depth_m

    if shallowest(t_a) <= 0.0:
        return t_hit
    return brentq(shallowest, t_a, t_hit, xtol=1e-15, rtol=4 * np.finfo(float).eps)


def _segment_scipy(model, method, x, t0, t1, u, rtol, atol, t_eval, onset_depth_m, budget,
                   stats):
    """Integrate one segment with a scipy OdeSolver stepped from Python."""
    from sphere_sim.model import dynamics as dyn
    fun, jac = model.at_voltages(u)
    samples = []
    i_eval = 0
    stats.n_rejected = stats.n_newton_failed = stats.n_onset_bounded = None
    solver = _scipy_solver(method, fun, jac, t0, x, t1, rtol, atol)
    check_electrodes = bool(model.flags[dyn.F_ELECTROSTATICS]) and model.n_beams > 0
    gaps_start = model.electrode_gaps(x)
    gaps = model.contact_gaps(x)
    gaps_end = np.empty_like(gaps)
    check_onset = onset_depth_m > 0 and gaps.size > 0
    p, flags, directions = model.p, model.flags, model.beam_directions
    while True:
        budget.check(solver.t, solver.y)
        t_a = solver.t
        message = solver.step()
        if solver.status == 'failed':
            _count_scipy(solver, stats)
            raise SolverError(f'{method} failed at t = {solver.t} s: {message}', solver.t,
                              solver.y.copy(), SolverStatus.STEP_TOO_SMALL
                              if 'step size' in str(message) else SolverStatus.FAILED)
        budget.steps += 1
        stats.n_steps += 1
        if check_electrodes and stats.n_steps % DOMAIN_CHECK_STEPS == 0:
            check_domain(model, solver.t, solver.y, u, gaps_start)
        t_b = solver.t
        dense = None
        restart = None
        # One compiled call per step: the test is timed as part of the library method's cost.
        if check_onset and gap_kernels.closed_too_deep(gaps, solver.y, p, flags, directions,
                                              onset_depth_m, gaps_end):
            dense = solver.dense_output()
            restart = _first_onset(model, dense, t_a, t_b, gaps > 0.0, onset_depth_m)
        t_stop = t_b if restart is None else restart
        while i_eval < t_eval.size and t_eval[i_eval] <= t_stop:
            if dense is None:
                dense = solver.dense_output()
            samples.append(dense(t_eval[i_eval]))
            i_eval += 1
        if restart is not None:
            _count_scipy(solver, stats)
            stats.n_onset_restarts += 1
            y_restart = dense(restart)
            solver = _scipy_solver(method, fun, jac, restart, y_restart, t1, rtol, atol,
                                   first_step=max(restart - t_a, 1e-12))
            gaps = model.contact_gaps(y_restart)
            continue
        gaps, gaps_end = gaps_end, gaps
        if solver.status == 'finished':
            break
    _count_scipy(solver, stats)
    x_eval = np.array(samples).T if samples else np.empty((model.n_states, 0))
    return solver.y.copy(), x_eval


def _count_scipy(solver, stats):
    stats.nfev += int(solver.nfev)
    stats.njev += int(solver.njev)
    stats.nlu += int(solver.nlu)


def _odeint_functions(model, u, budget, gaps_start):
    """odeint's right-hand side and Jacobian at the voltages ``u``.

    odeint returns only between its output times: the wall clock and the model's domain are
    checked where it asks for a Jacobian (as CVODE's are; a stall asks for many), and an
    error raised there ends the call. The Jacobian is d f_i / d x_j in row i, column j, as
    the model returns it: odeint's ``col_deriv=False`` (``ODEINT_COL_DERIV``) reads it so.
    """
    fun, jac = model.at_voltages(u)

    def dfun(t, x):
        budget.check(t, x)
        check_domain(model, t, x, u, gaps_start)
        return jac(t, x)

    return fun, dfun



def _odeint_status(message):
    if message.startswith('Excess work'):  # mxstep: the step budget
        return SolverStatus.BUDGET_EXCEEDED
    if message.startswith('Repeated'):  # LSODA's error or Newton failures at the minimum step
        return SolverStatus.STEP_TOO_SMALL
    return SolverStatus.FAILED


def _odeint_call(fun, dfun, x, times, rtol, atol, budget, stats):
    """States at ``times`` (rows) from ``x`` at times[0], one odeint call that never steps
    past times[-1]; counts its work into ``stats`` and the budget."""
    mxstep = int(min(ODEINT_MAX_MXSTEP, max(1, budget.max_steps - budget.steps)))
    with warnings.catch_warnings():
        warnings.simplefilter('ignore', scipy.integrate.ODEintWarning)
        ys, info = scipy.integrate.odeint(
            fun, x, times, Dfun=dfun, col_deriv=ODEINT_COL_DERIV, full_output=True,
            rtol=rtol, atol=atol, tcrit=times[-1:], mxstep=mxstep, tfirst=True)
    ok = info['message'] == ODEINT_SUCCESS
    # On a failure the entries after the failed output time are not written.
    last = times.size - 2 if ok else int(np.argmin(info['tcur'] >= times[1:]))
    stats.nfev += int(info['nfe'][last])
    stats.njev += int(info['nje'][last])
    stats.n_steps += int(info['nst'][last])
    budget.steps += int(info['nst'][last])
    if not ok:
        # LSODA leaves the state where it stopped in the failed output time's row.
        t_fail, x_fail = float(info['tcur'][last]), ys[last + 1].copy()
        raise SolverError(f'odeint failed at t = {t_fail} s: {info["message"]}', t_fail,
                          x_fail, _odeint_status(info['message']))
    return ys


def _odeint_grid(t, t1, t_eval):
    """The next call's times from ``t``: check points and the samples up to at most
    ODEINT_CHUNK_POINTS check periods later; no call is left a sliver before ``t1``."""
    t_stop = t + ODEINT_CHUNK_POINTS * ODEINT_CHECK_PERIOD_S
    if t_stop >= t1 - ODEINT_CHECK_PERIOD_S:
        t_stop = t1
    n = max(1, math.ceil((t_stop - t) / ODEINT_CHECK_PERIOD_S))
    checks = np.linspace(t, t_stop, n + 1)
    checks[-1] = t_stop
    return np.union1d(checks, t_eval[(t_eval > t) & (t_eval <= t_stop)])


def _odeint_onset(model, call, t_a, x_a, t_b, x_b, onset_depth_m):
    """Where to go on after a contact open at ``t_a`` was found closed deeper than the allowed
    depth at the next check point ``t_b`` (state ``x_b``): ``(restarted, t, x)``.

    The interval is integrated again from ``t_a``, where LSODA starts afresh with a small step.
    If that lands on the call's contact gaps at ``t_b`` within the allowed depth, the call
    resolved the onset (a closure at several cm/s covers the depth many times over between
    check points) and goes on from ``t_b``. If not, it stepped over the onset: the search
    narrows the interval on ever finer grids to a point where the contact has closed by half
    to all of the allowed depth, and odeint restarts there (or at the end of the search's
    integration, if that closes nothing).
    """
    open_mask = model.contact_gaps(x_a) > 0.0
    times = np.linspace(t_a, t_b, ODEINT_LOCATE_POINTS + 1)
    ys = call(x_a, times)
    agreement_m = ODEINT_ONSET_AGREEMENT * onset_depth_m
    if np.max(np.abs(model.contact_gaps(ys[-1]) - model.contact_gaps(x_b))) <= agreement_m:
        return False, t_b, x_b
    for _ in range(ODEINT_LOCATE_LEVELS):
        shallowest = np.array([np.min(model.contact_gaps(y)[open_mask]) for y in ys[1:]])
        closed = np.flatnonzero(shallowest <= -0.5 * onset_depth_m)
        if closed.size == 0:
            return True, times[-1], ys[-1]
        j = int(closed[0]) + 1
        if shallowest[j - 1] >= -onset_depth_m:
            break
        times = np.linspace(times[j - 1], times[j], ODEINT_LOCATE_POINTS + 1)
        ys = call(ys[j - 1], times)
    return True, times[j], ys[j]


def _odeint_scan(model, call, times, ys, onset_depth_m, scratch, stats):
    """``(row, t, x)``: the last row of a call's states ``ys`` that stands, and the time and
    state to go on from (the last row's, or a restart at an onset the call stepped over)."""
    k0 = 0
    while True:
        k = gap_kernels.first_deep_closure(ys[k0:], model.p, model.flags,
                                           model.beam_directions, onset_depth_m, *scratch)
        if k < 0:
            return times.size - 1, times[-1], ys[-1]
        k += k0
        restarted, t_next, x_next = _odeint_onset(model, call, times[k - 1], ys[k - 1],
                                                  times[k], ys[k], onset_depth_m)
        if restarted:
            stats.n_onset_restarts += 1
            return k - 1, t_next, x_next
        k0 = k


def _segment_odeint(model, x, t0, t1, u, rtol, atol, t_eval, onset_depth_m, budget, stats):
    """Integrate one segment with scipy's odeint (LSODA), restarting at contact onsets."""
    stats.n_rejected = stats.n_newton_failed = stats.n_onset_bounded = None
    fun, dfun = _odeint_functions(model, u, budget, model.electrode_gaps(x))

    def call(x_start, times):
        return _odeint_call(fun, dfun, x_start, times, rtol, atol, budget, stats)

    n_gaps = gap_kernels.n_contacts(model.flags)
    check_onset = onset_depth_m > 0 and n_gaps > 0
    scratch = (np.empty(max(1, n_gaps)), np.empty(max(1, n_gaps)))
    samples, t, x = [], t0, np.array(x, dtype=float)
    while t < t1:
        budget.check(t, x)
        times = _odeint_grid(t, t1, t_eval)
        ys = call(x, times)
        last, t_next, x_next = (_odeint_scan(model, call, times, ys, onset_depth_m, scratch,
                                             stats) if check_onset
                                else (times.size - 1, times[-1], ys[-1]))
        rows = np.flatnonzero(np.isin(times[:last + 1], t_eval) & (times[:last + 1] > t)
                              & (times[:last + 1] < t_next))
        samples.extend(ys[rows])
        if np.any(t_eval == t_next):
            samples.append(x_next)
        t, x = t_next, np.array(x_next)
    budget.check(t, x)
    x_eval = np.array(samples).T if samples else np.empty((model.n_states, 0))
    return x, x_eval

def _cvode_events(model, open_index, onset_depth_m):
    """CVODE's root functions: the gaps of the contacts open at the segment's start, plus half
    the onset depth. CVODE evaluates them at every step, so they make one compiled call."""
    p, flags, directions = model.p, model.flags, model.beam_directions
    gaps = np.empty(max(1, gap_kernels.n_contacts(flags)))
    offset = 0.5 * onset_depth_m

    def eventsfn(t, y, events):
        gap_kernels.contact_gaps(y, p, flags, directions, gaps)
        np.add(gaps[open_index], offset, out=events)

    return eventsfn


def _segment_cvode(model, x, t0, t1, u, rtol, atol, t_eval, onset_depth_m, budget, stats):
    """Integrate one segment with SUNDIALS CVODE (BDF, dense), restarting at contact onsets."""
    from sksundae.cvode import CVODE

    stats.n_steps = stats.n_rejected = None
    stats.n_newton_failed = stats.n_onset_bounded = None

    fun, jac = model.at_voltages(u)

    def rhsfn(t, y, yp):
        fun(t, y, yp)

    gaps_start = model.electrode_gaps(x)

    def jacfn(t, y, yp, JJ):
        # CVODE asks for Jacobians often when it stalls: the budgets and the model's domain
        # are checked there.
        budget.check(t, y)
        check_domain(model, t, y, u, gaps_start)
        JJ[:, :] = jac(t, y)

    samples = []
    t = t0
    x = np.array(x, dtype=float)
    while True:
        budget.check(t, x)
        gaps = model.contact_gaps(x)
        open_index = np.flatnonzero(gaps > 0.0) if onset_depth_m > 0 else np.array([], int)
        options = {'method': 'BDF', 'rtol': rtol, 'atol': atol, 'jacfn': jacfn,
                   'max_num_steps': 1_000_000, 'linsolver': 'dense'}
        if open_index.size:
            eventsfn = _cvode_events(model, open_index, onset_depth_m)
            eventsfn.terminal = [True] * open_index.size
            eventsfn.direction = [-1] * open_index.size
            options.update(eventsfn=eventsfn, num_events=int(open_index.size))
        pending = t_eval[t_eval > t]
        tspan = np.concatenate([[t], pending]) if pending.size and pending[-1] >= t1 \
            else np.concatenate([[t], pending, [t1]])
        if tspan.size == 2:
            tspan = np.array([t, 0.5 * (t + t1), t1])
        result = CVODE(rhsfn, **options).solve(tspan, x)
        stats.nfev += int(result.nfev)
        stats.njev += int(result.njev)
        if not result.success:
            raise SolverError(f'CVODE failed at t = {result.t[-1]} s: {result.message}',
                              float(result.t[-1]), np.array(result.y[-1]))
        y = np.asarray(result.y)
        ts = np.asarray(result.t)
        keep = np.isin(ts, t_eval)
        samples.extend(y[keep])
        x = np.array(y[-1])
        t = float(ts[-1])
        if result.status == 2 and t < t1:  # stopped at a contact onset: restart there
            stats.n_onset_restarts += 1
            if keep[-1]:
                samples.pop()
            continue
        break
    x_eval = np.array(samples).T if samples else np.empty((model.n_states, 0))
    return x, x_eval


def simulate(model, x0, t_end_s, programme=None, rtol=1e-6, atol=None, method='fast',
             sample_period_s=1e-4, t_start_s=0.0, max_wall_s=None, max_steps=None,
             onset_depth_m=None):
    """Integrate ``model`` from ``x0`` to ``t_end_s`` under a pulse programme.

    Parameters
    ----------
    model : Model
    x0 : ndarray, shape (n_states,)
    t_end_s : float
    programme : PulseProgramme or VoltageSchedule, optional
        The voltages, constant between its ``edges()``; defaults to the scene's programme.
    rtol : float
    atol : float or ndarray, optional
        Defaults to ``rtol * state_scale(model)``.
    method : str
        One of :data:`METHODS`.
    sample_period_s : float
        Output sampling; every segment boundary is sampled too.
    max_wall_s : float, optional
        Wall-clock budget (s), DEFAULT_MAX_WALL_S if None; exceeding it raises
        :class:`SolverError` (BUDGET_EXCEEDED).
    max_steps : int, optional
        Accepted-step budget, DEFAULT_MAX_STEPS if None.
    onset_depth_m : float, optional
        Deepest closure of an open contact within one step (m); default
        :func:`default_onset_depth_m`, 0 disables the check.

    Returns
    -------
    Trajectory

    Raises
    ------
    SolverError
        With the time and state where the integration stopped.
    """
    programme = model.scene.programme if programme is None else programme
    if not isinstance(programme, PulseProgramme | VoltageSchedule):
        raise TypeError('programme must be a PulseProgramme or a VoltageSchedule')
    if method not in METHODS:
        raise ValueError(f'method must be one of {METHODS}, got {method!r}')
    atol = rtol * state_scale(model) if atol is None else atol
    atol = np.broadcast_to(np.asarray(atol, dtype=float), (model.n_states,)).copy()
    onset = default_onset_depth_m(model) if onset_depth_m is None else float(onset_depth_m)
    budget = _Budget(DEFAULT_MAX_WALL_S if max_wall_s is None else max_wall_s,
                     DEFAULT_MAX_STEPS if max_steps is None else max_steps)
    stats = SolverStats(method=method)
    x = np.array(x0, dtype=float)
    ts, xs, us = [np.array([t_start_s])], [x[:, None]], []
    bounds = segment_times(programme, t_start_s, t_end_s)
    for t0, t1 in itertools.pairwise(bounds):
        u = programme.voltages_at(t0, model.beams)
        n_samples = max(1, math.ceil((t1 - t0) / sample_period_s))
        t_eval = np.linspace(t0, t1, n_samples + 1)[1:]
        t_eval[-1] = t1
        if method == 'fast':
            x, x_eval = _segment_fast(model, x, t0, t1, u, rtol, atol, t_eval, onset, budget,
                                      stats)
        elif method == 'odeint':
            x, x_eval = _segment_odeint(model, x, t0, t1, u, rtol, atol, t_eval, onset, budget,
                                        stats)
        elif method == 'CVODE':
            x, x_eval = _segment_cvode(model, x, t0, t1, u, rtol, atol, t_eval, onset, budget,
                                       stats)
        else:
            x, x_eval = _segment_scipy(model, method, x, t0, t1, u, rtol, atol, t_eval, onset,
                                       budget, stats)
        if x_eval.shape[1] != t_eval.size or not np.all(np.isfinite(x_eval)):
            raise SolverError(f'{method}: segment [{t0}, {t1}] s ended without all samples or '
                              'with a non-finite state', t0, x)
        x = x_eval[:, -1].copy()
        stats.n_segments += 1
        ts.append(t_eval)
        xs.append(x_eval)
        us.append(np.repeat(u[:, None], t_eval.size, axis=1))
    stats.wall_time_s = time.perf_counter() - budget.started
    u_all = np.concatenate([programme.voltages_at(t_start_s, model.beams)[:, None], *us], axis=1)
    return Trajectory(model, np.concatenate(ts), np.concatenate(xs, axis=1), u_all,
                      SolverStatus.SUCCESS, stats)


def solve(model, t_span, rtol=DEFAULT_RTOL, atol=None, method=DEFAULT_METHOD,
          x0=None, programme=None, sample_period_s=1e-4, max_wall_s=None, max_steps=None,
          onset_depth_m=None):
    """Integrate an assembled model over ``t_span``.

    Parameters
    ----------
    model : Model
        From :func:`~sphere_sim.model.assembly.assemble`; its scene's initial state is used
        unless ``x0`` is given.
    t_span : tuple of float
        (t_start_s, t_end_s).
    rtol : float
    atol : float or ndarray, optional
        Defaults to ``rtol * state_scale(model)``.
    method : str
        One of :data:`METHODS`; ``'fast'`` is the compiled Radau IIA.
    x0 : ndarray, shape (n_states,), optional
        Defaults to the scene's initial state.
    programme : PulseProgramme, optional
        Defaults to the scene's programme.
    sample_period_s, max_wall_s, max_steps, onset_depth_m
        As for :func:`simulate`.

    Returns
    -------
    Trajectory
        ``trajectory.stats`` holds steps, rejected steps, nfev, njev, nlu and wall time.
    """
    if x0 is None:
        x0 = initial_state(model)
    t_start_s, t_end_s = (float(t) for t in t_span)
    return simulate(model, x0, t_end_s, programme, rtol=rtol, atol=atol, method=method,
                    sample_period_s=sample_period_s, t_start_s=t_start_s, max_wall_s=max_wall_s,
                    max_steps=max_steps, onset_depth_m=onset_depth_m)
