"""The library methods' segment drivers: scipy's solvers, odeint and CVODE.

Each integrates one :class:`~sphere_sim.integrate.segment.Segment` and is listed in
:data:`sphere_sim.integrate.solve.SEGMENT_METHODS`. None steps over a contact onset: a contact
open at the start of a step may not close deeper than ``onset_depth_m`` within it. The scipy
methods check the end of each step (a check of interior points on every step would cost scipy
more than its own stepping) and, when it is closed too deep, stop at the onset, found by root
finding on the dense output, and restart there; CVODE does the same with its own root finding.
odeint returns only at the times it is asked for, so it is asked for a grid of check points
(ODEINT_CHECK_PERIOD_S) besides the samples: a contact open at one check point may not close
deeper than ``onset_depth_m`` by the next; when one does, the interval is integrated again on
finer grids down to the onset, and odeint restarts there.
"""

import math
import warnings
from collections.abc import Callable
from typing import Any

import numpy as np
import scipy.integrate
from numpy.typing import NDArray
from scipy.optimize import brentq

from sphere_sim.integrate.segment import (
    Budget,
    Segment,
    SolverError,
    SolverStats,
    SolverStatus,
    check_domain,
)
from sphere_sim.model import gaps as gap_kernels
from sphere_sim.model.assembly import Model

IMPLICIT_METHODS = ('Radau', 'BDF', 'LSODA')
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

# What Model.at_voltages returns: ``fun(t, x, out=None)`` and ``jac(t, x)``.
RhsFunction = Callable[..., NDArray[np.float64]]
JacobianFunction = Callable[[float, NDArray[np.float64]], NDArray[np.float64]]
# One odeint call from a state over output times: the states at those times (rows).
OdeintCall = Callable[[NDArray[np.float64], NDArray[np.float64]], NDArray[np.float64]]


def _scipy_solver(method: str, fun: RhsFunction, jac: JacobianFunction, t0: float,
                  x: NDArray[np.float64], t1: float, rtol: float, atol: NDArray[np.float64],
                  first_step: float | None = None) -> Any:
    cls = getattr(scipy.integrate, method)
    options: dict[str, Any] = {'rtol': rtol, 'atol': atol}
    if method in IMPLICIT_METHODS:
        options['jac'] = jac
    if first_step is not None:
        options['first_step'] = first_step
    return cls(fun, t0, x, t1, **options)


def _first_onset(model: Model, dense: Callable[[float], NDArray[np.float64]], t_a: float,
                 t_b: float, open_mask: NDArray[np.bool_], onset_depth_m: float) -> float | None:
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

    def shallowest(t: float) -> float:
        return float(np.min(model.contact_gaps(dense(t))[open_mask])) + 0.5 * onset_depth_m

    if shallowest(t_a) <= 0.0:
        return t_hit
    return brentq(shallowest, t_a, t_hit, xtol=1e-15, rtol=4 * np.finfo(float).eps)


def segment_scipy(method: str, seg: Segment) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Integrate one segment with a scipy OdeSolver stepped from Python."""
    from sphere_sim.model import dynamics as dyn
    model, x, t0, t1, u = seg.model, seg.x, seg.t0, seg.t1, seg.u
    rtol, atol, t_eval, onset_depth_m = seg.rtol, seg.atol, seg.t_eval, seg.onset_depth_m
    budget, stats = seg.budget, seg.stats
    fun, jac = model.at_voltages(u)
    samples: list[NDArray[np.float64]] = []
    i_eval = 0
    stats.n_rejected = stats.n_newton_failed = stats.n_onset_bounded = None
    assert stats.n_steps is not None  # scipy's steps are counted
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
        dense: Any = None  # scipy's DenseOutput
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


def _count_scipy(solver: Any, stats: SolverStats) -> None:
    stats.nfev += int(solver.nfev)
    stats.njev += int(solver.njev)
    stats.nlu += int(solver.nlu)


def _odeint_functions(model: Model, u: NDArray[np.float64], budget: Budget,
                      gaps_start: NDArray[np.float64]) -> tuple[RhsFunction, JacobianFunction]:
    """odeint's right-hand side and Jacobian at the voltages ``u``.

    odeint returns only between its output times: the wall clock and the model's domain are
    checked where it asks for a Jacobian (as CVODE's are; a stall asks for many), and an
    error raised there ends the call. The Jacobian is d f_i / d x_j in row i, column j, as
    the model returns it: odeint's ``col_deriv=False`` (``ODEINT_COL_DERIV``) reads it so.
    """
    fun, jac = model.at_voltages(u)

    def dfun(t: float, x: NDArray[np.float64]) -> NDArray[np.float64]:
        budget.check(t, x)
        check_domain(model, t, x, u, gaps_start)
        return jac(t, x)

    return fun, dfun


def _odeint_status(message: str) -> SolverStatus:
    if message.startswith('Excess work'):  # mxstep: the step budget
        return SolverStatus.BUDGET_EXCEEDED
    if message.startswith('Repeated'):  # LSODA's error or Newton failures at the minimum step
        return SolverStatus.STEP_TOO_SMALL
    return SolverStatus.FAILED


def _odeint_call(fun: RhsFunction, dfun: JacobianFunction, x: NDArray[np.float64],
                 times: NDArray[np.float64], rtol: float, atol: NDArray[np.float64],
                 budget: Budget, stats: SolverStats) -> NDArray[np.float64]:
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
    assert stats.n_steps is not None  # odeint's steps are counted
    stats.n_steps += int(info['nst'][last])
    budget.steps += int(info['nst'][last])
    if not ok:
        # LSODA leaves the state where it stopped in the failed output time's row.
        t_fail, x_fail = float(info['tcur'][last]), ys[last + 1].copy()
        raise SolverError(f'odeint failed at t = {t_fail} s: {info["message"]}', t_fail,
                          x_fail, _odeint_status(info['message']))
    return ys


def _odeint_grid(t: float, t1: float, t_eval: NDArray[np.float64]) -> NDArray[np.float64]:
    """The next call's times from ``t``: check points and the samples up to at most
    ODEINT_CHUNK_POINTS check periods later; no call is left a sliver before ``t1``."""
    t_stop = t + ODEINT_CHUNK_POINTS * ODEINT_CHECK_PERIOD_S
    if t_stop >= t1 - ODEINT_CHECK_PERIOD_S:
        t_stop = t1
    n = max(1, math.ceil((t_stop - t) / ODEINT_CHECK_PERIOD_S))
    checks = np.linspace(t, t_stop, n + 1)
    checks[-1] = t_stop
    return np.union1d(checks, t_eval[(t_eval > t) & (t_eval <= t_stop)])


def _odeint_onset(model: Model, call: OdeintCall, t_a: float, x_a: NDArray[np.float64],
                  t_b: float, x_b: NDArray[np.float64],
                  onset_depth_m: float) -> tuple[bool, float, NDArray[np.float64]]:
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


def _odeint_scan(model: Model, call: OdeintCall, times: NDArray[np.float64],
                 ys: NDArray[np.float64], onset_depth_m: float,
                 scratch: tuple[NDArray[np.float64], NDArray[np.float64]],
                 stats: SolverStats) -> tuple[int, float, NDArray[np.float64]]:
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


def segment_odeint(seg: Segment) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Integrate one segment with scipy's odeint (LSODA), restarting at contact onsets."""
    model, x, t0, t1, u = seg.model, seg.x, seg.t0, seg.t1, seg.u
    rtol, atol, t_eval, onset_depth_m = seg.rtol, seg.atol, seg.t_eval, seg.onset_depth_m
    budget, stats = seg.budget, seg.stats
    stats.n_rejected = stats.n_newton_failed = stats.n_onset_bounded = None
    fun, dfun = _odeint_functions(model, u, budget, model.electrode_gaps(x))

    def call(x_start: NDArray[np.float64], times: NDArray[np.float64]) -> NDArray[np.float64]:
        return _odeint_call(fun, dfun, x_start, times, rtol, atol, budget, stats)

    n_gaps = gap_kernels.n_contacts(model.flags)
    check_onset = onset_depth_m > 0 and n_gaps > 0
    scratch = (np.empty(max(1, n_gaps)), np.empty(max(1, n_gaps)))
    samples: list[NDArray[np.float64]] = []
    t, x = t0, np.array(x, dtype=float)
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


def _cvode_events(model: Model, open_index: NDArray[np.intp], onset_depth_m: float
                  ) -> Callable[[float, NDArray[np.float64], NDArray[np.float64]], None]:
    """CVODE's root functions: the gaps of the contacts open at the segment's start, plus half
    the onset depth. CVODE evaluates them at every step, so they make one compiled call."""
    p, flags, directions = model.p, model.flags, model.beam_directions
    gaps = np.empty(max(1, gap_kernels.n_contacts(flags)))
    offset = 0.5 * onset_depth_m

    def eventsfn(t: float, y: NDArray[np.float64], events: NDArray[np.float64]) -> None:
        gap_kernels.contact_gaps(y, p, flags, directions, gaps)
        np.add(gaps[open_index], offset, out=events)

    return eventsfn


def segment_cvode(seg: Segment) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Integrate one segment with SUNDIALS CVODE (BDF, dense), restarting at contact onsets."""
    from sksundae.cvode import CVODE

    model, x, t0, t1, u = seg.model, seg.x, seg.t0, seg.t1, seg.u
    rtol, atol, t_eval, onset_depth_m = seg.rtol, seg.atol, seg.t_eval, seg.onset_depth_m
    budget, stats = seg.budget, seg.stats
    stats.n_steps = stats.n_rejected = None
    stats.n_newton_failed = stats.n_onset_bounded = None

    fun, jac = model.at_voltages(u)

    def rhsfn(t: float, y: NDArray[np.float64], yp: NDArray[np.float64]) -> None:
        fun(t, y, yp)

    gaps_start = model.electrode_gaps(x)

    def jacfn(t: float, y: NDArray[np.float64], yp: NDArray[np.float64],
              JJ: NDArray[np.float64]) -> None:
        # CVODE asks for Jacobians often when it stalls: the budgets and the model's domain
        # are checked there.
        budget.check(t, y)
        check_domain(model, t, y, u, gaps_start)
        JJ[:, :] = jac(t, y)

    samples: list[NDArray[np.float64]] = []
    t = t0
    x = np.array(x, dtype=float)
    while True:
        budget.check(t, x)
        gaps = model.contact_gaps(x)
        open_index = np.flatnonzero(gaps > 0.0) if onset_depth_m > 0 else np.array([], int)
        options = {'method': 'BDF', 'rtol': rtol, 'atol': atol, 'jacfn': jacfn,
                   'max_num_steps': 1_000_000, 'linsolver': 'dense'}
        if open_index.size:
            # sksundae reads the events' terminal and direction from the function's attributes.
            eventsfn: Any = _cvode_events(model, open_index, onset_depth_m)
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
