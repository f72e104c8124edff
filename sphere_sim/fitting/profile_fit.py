"""A global search and profile-likelihood intervals for a misfit given as residuals on the unit
cube (each parameter's scaled coordinate, [0, 1] over its declared range).

The global search is a multi-start: a Latin hypercube over the whole cube, local least squares
from its lowest points, the lowest end kept. A descent by differences stops on whatever side of
a step it starts on; starts spread over the declared ranges see the basins a single start
misses (docs/identification.md, "On the paper's device").

The interval of each parameter is read from its profile: the parameter is stepped away from
the optimum, the others re-minimised at each step (from where the optimum's linearisation puts
them, on the optimum's Jacobian carried from step to step), and the 95 % interval ends where the
profile's sum of squares has risen by :data:`CHI2_95` over the minimum. Unlike the local
slope's interval, a profile follows a curved or flattening valley and reports where the misfit
actually rises. A parameter whose interval reaches a bound of its range, or spans more than
:data:`DETERMINED_SHARE` of it, is *undetermined*: the experiments do not pin it, and the range
is what is known.

Pure numerics, no model: the caller's residual function does the simulating and bears the cost,
which :class:`CostLimitError` bounds (``max_evaluations`` distinct points). Points that do not
depend on one another (the multi-start's, a Jacobian's columns) are asked for together: a
residual function with a ``many(points)`` method gets them as one batch, which a pool of
workers shares out as one queue instead of idling at the end of each point's.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

Residuals = Callable[[NDArray[np.float64]], NDArray[np.float64]]

# The 95 % point of chi-square with one degree of freedom: a profile's sum of squares rises by
# this much at the ends of a 95 % interval (Wilks).
CHI2_95 = 3.841458820694124
# Wilks' rise reads an interval only where the fit reaches the noise: a sum of squares above
# chi-square's 99.9 % point for its degrees of freedom says the residuals at the optimum are
# not the noise (the shipped example's six, started in a cell of the kicks' misfit 270 above
# the truth's: every profile rose by CHI2_95 within 0.007 of its range, every one missing the
# truth, each step crossing into a higher cell).
NOISE_QUANTILE = 0.999
# A parameter is determined when its 95 % interval spans at most this share of its scaled range
# (and reaches neither bound): issue 48's criterion.
DETERMINED_SHARE = 0.1
# Forward-difference step of the local least squares (scaled coordinates): large enough that a
# misfit quantised by its own simulations (a threshold bisected to 0.01 V, say) reads a slope
# rather than a step, small enough to stay inside a valley a few hundredths wide.
FD_STEP_UNIT = 0.01
# The local least squares stops when a step moves the parameters by less than XTOL (below the
# narrowest interval of interest) or the cost by less than FTOL of itself.
XTOL = 1e-4
FTOL = 1e-6
MAX_DESCENT_EVALUATIONS = 40
# A profile step re-minimises the others by Levenberg-Marquardt on a Jacobian carried from the
# optimum and updated by Broyden's rule after each accepted step, with no difference steps of
# its own: the kicks' misfit has thin sheets where one kick lands on its other branch
# (paper_b's protocol: two of 20 kicks, 50 standard deviations off, 0.005 to 0.04 of the range
# from the optimum), and a difference step that lands on one turns the Jacobian to noise (a
# trust-region descent with difference Jacobians then crawled for 64 evaluations at one
# profile step). A trial on a sheet is merely rejected. It stops when a step would lower the
# sum of squares by less than PROFILE_CHI2_TOL, far below the CHI2_95 the ends are read at, or
# after MAX_PROFILE_STEP_EVALUATIONS. A step shorter than the difference step the Jacobian was
# taken with does not update it: the misfit jitters with the integrator's step sequence
# (paper_b: by about 0.5 in chi-square between points 1e-4 apart), and divided by so short a
# step the jitter would read as slope.
PROFILE_CHI2_TOL = 0.1
MAX_PROFILE_STEP_EVALUATIONS = 10
# Levenberg-Marquardt's damping (a share of J^T J's diagonal) after the first rejected step,
# and its factor on each rejection (divided by it on each acceptance).
FIRST_DAMPING = 1e-2
DAMPING_FACTOR = 10.0
# The profile's first step is this share of the 95 % half-width the local curvature predicts
# (so that a quadratic misfit is bracketed by the second step), kept within [MIN_STEP, MAX_STEP].
# Each further step aims OVERSHOOT beyond where a quadratic through the optimum and the last
# step would reach CHI2_95 (so that it brackets the crossing rather than falls short of it),
# at least MIN_GROWTH and at most MAX_GROWTH times the last, at most MAX_PROFILE_STEPS per side.
# Where the curvature misleads (paper_b's d_B,phi: a Jacobian that took a step onto a kick's
# sheet read it far steeper than its profile), a first step that rises by a tenth of CHI2_95
# is followed by one nearly four times as long, not by two doublings.
FIRST_STEP_SHARE = 0.7
MIN_STEP = 1e-3
MAX_STEP = 0.25
OVERSHOOT = 1.2
MIN_GROWTH = 1.5
MAX_GROWTH = 4.0
MAX_PROFILE_STEPS = 12
# Ridge added to J^T J before inverting it for the first step: a direction the residuals do not
# see gets a large step (clipped to MAX_STEP) instead of none.
RIDGE = 1e-6
# A coordinate the residuals see: moved by SEEN_STEP_UNIT of its scaled range from a point, it
# moves some residual by at least SEEN_RESIDUAL standard deviations. A tenth of the range is far
# beyond any interval called determined, and a residual's standard deviation is what a fit
# can tell apart: a coordinate that moves none by one over a tenth of its range is one those
# residuals cannot pin, and a search over it on them alone ends wherever its starts fell.
SEEN_STEP_UNIT = 0.1
SEEN_RESIDUAL = 1.0
# A profile point lower than the optimum by this much means the optimum was not the global one.
LOWER_BY = 0.5
# Then the descent starts again from the lowest point seen and the profiles are read about its
# end, this many times at most: intervals read about a point that is not the lowest are too
# narrow where the misfit falls.
PROFILE_RESTARTS = 1
# A difference step that moves one residual by more than this many standard deviations may
# have crossed a sheet, and the step the other way is taken too; the smaller column is the
# slope, since a sheet only adds (the shipped example's six at the polish's end: forward steps
# of z_G, mu_s and d_B,phi each moved one kick by 17 to 18 standard deviations, columns of norm
# 4800 to 5200, against 100 to 550 backward and at a third of the step either way).
SHEET_RESIDUAL = 5.0
# The polish takes a fresh difference Jacobian when the carried one stops lowering the misfit,
# at most this many times: one Jacobian carried from a start far from the optimum stalls (the
# shipped example's three parameters: from the thresholds' optimum, a sum of squares of 2721,
# one round ended at 382, and the profiles about it found points 300 lower and started again).
POLISH_ROUNDS = 6


class CostLimitError(RuntimeError):
    """The residual function was asked for more distinct points than allowed."""


class _Counted:
    """The caller's residuals, each distinct point evaluated once, at most ``limit`` points;
    :meth:`many` passes a batch to the residuals' own ``many`` where they have one."""

    def __init__(self, fun: Residuals, limit: int) -> None:
        self.fun, self.limit = fun, limit
        self.cache: dict[tuple[float, ...], NDArray[np.float64]] = {}

    @property
    def evaluations(self) -> int:
        return len(self.cache)

    def __call__(self, u: ArrayLike) -> NDArray[np.float64]:
        key = tuple(float(v) for v in np.asarray(u, dtype=float))
        if key not in self.cache:
            if len(self.cache) >= self.limit:
                raise CostLimitError(f'the cost limit of {self.limit} evaluations is reached')
            self.cache[key] = np.asarray(self.fun(np.array(key)), dtype=float)
        return self.cache[key]

    def many(self, points: Sequence[ArrayLike]) -> list[NDArray[np.float64]]:
        """The residuals at each of ``points``, the new ones evaluated in one batch. Over the
        limit, the points within it are evaluated (in order) and then CostLimitError is
        raised, as evaluating them one by one would."""
        keys = [tuple(float(v) for v in np.asarray(u, dtype=float)) for u in points]
        new = list(dict.fromkeys(k for k in keys if k not in self.cache))
        room = max(self.limit - len(self.cache), 0)
        todo = [np.array(k) for k in new[:room]]
        # Nothing new (all cached) asks the residuals for nothing, not for an empty batch.
        values = _batch(self.fun, todo) if todo else []
        for key, value in zip(new[:room], values, strict=True):
            self.cache[key] = np.asarray(value, dtype=float)
        if len(new) > room:
            raise CostLimitError(f'the cost limit of {self.limit} evaluations is reached')
        return [self.cache[k] for k in keys]

    def chi2(self, u: ArrayLike) -> float:
        return float(np.sum(self(u) ** 2))

    def lowest(self) -> tuple[NDArray[np.float64], float]:
        """The lowest point evaluated so far, and its sum of squares."""
        best = min(self.cache, key=lambda k: float(np.sum(self.cache[k] ** 2)))
        return np.array(best), float(np.sum(self.cache[best] ** 2))


def reaches_the_noise(chi2: float, residuals: int, parameters: int) -> bool:
    """Whether a fit's sum of squares is one the noise gives: at most chi-square's
    :data:`NOISE_QUANTILE` point with ``residuals - parameters`` degrees of freedom (one at
    least)."""
    from scipy.stats import chi2 as chi_square

    return chi2 <= float(chi_square.ppf(NOISE_QUANTILE, max(residuals - parameters, 1)))


@dataclasses.dataclass(frozen=True)
class ProfileInterval:
    """The 95 % profile interval of one parameter (scaled coordinates)."""

    index: int
    low_u: float
    high_u: float
    low_at_bound: bool  # the profile reached the range's bottom without rising by CHI2_95
    high_at_bound: bool
    complete: bool  # False when the cost limit stopped the profile
    points: tuple[tuple[float, float], ...]  # (u, profile sum of squares), as walked

    @property
    def width_u(self) -> float:
        return self.high_u - self.low_u

    @property
    def determined(self) -> bool:
        return (self.complete and not self.low_at_bound and not self.high_at_bound
                and self.width_u <= DETERMINED_SHARE)


@dataclasses.dataclass(frozen=True)
class ProfileFit:
    u: NDArray[np.float64]  # the lowest point found
    chi2: float
    intervals: tuple[ProfileInterval, ...]
    evaluations: int
    cost_limited: bool  # the limit stopped the search or a profile
    lower_found: bool  # a profile went lower than the optimum, still after PROFILE_RESTARTS


def local_minimum(fun: _Counted, u0: ArrayLike,
                  free: Sequence[int]) -> tuple[NDArray[np.float64], float,
                                                NDArray[np.float64]]:
    """Bounded least squares (trust-region reflective) over the ``free`` coordinates from
    ``u0``, the others held. Returns (u, sum of squares, Jacobian of the free columns).

    The Jacobian is scipy's ``'2-point'`` at ``diff_step`` :data:`FD_STEP_UNIT` (on the unit
    cube its step is that, backward where forward would leave the cube), its columns
    evaluated as one batch."""
    from scipy.optimize import least_squares

    base = np.asarray(u0, dtype=float).copy()
    free = list(free)

    def full(x: NDArray[np.float64]) -> NDArray[np.float64]:
        v = base.copy()
        v[free] = x
        return v

    if not free:
        r = fun(base)
        return base, float(np.sum(r ** 2)), np.zeros((r.size, 0))
    x0 = np.clip(base[free], 1e-6, 1.0 - 1e-6)

    def jac(x: NDArray[np.float64]) -> NDArray[np.float64]:
        shifted, steps = [], []
        for j in range(x.size):
            moved = x.copy()
            moved[j] += FD_STEP_UNIT if x[j] + FD_STEP_UNIT <= 1.0 else -FD_STEP_UNIT
            shifted.append(full(moved))
            steps.append(moved[j] - x[j])  # the step as represented, as scipy divides by
        r0, *rs = fun.many([full(x), *shifted])
        return np.column_stack([(r - r0) / h for r, h in zip(rs, steps, strict=True)])

    sol = least_squares(lambda x: fun(full(x)), x0, jac=jac, bounds=(0.0, 1.0),
                        method='trf', x_scale=1.0, xtol=XTOL, ftol=FTOL,
                        max_nfev=MAX_DESCENT_EVALUATIONS)
    u = full(sol.x)
    return u, float(np.sum(fun(u) ** 2)), np.asarray(sol.jac, dtype=float)


def carried_minimum(fun: Callable[[NDArray[np.float64]], NDArray[np.float64]], u0: ArrayLike,
                    free: Sequence[int], jac: NDArray[np.float64]
                    ) -> tuple[NDArray[np.float64], float, NDArray[np.float64]]:
    """Levenberg-Marquardt over the ``free`` coordinates from ``u0`` (kept in the cube) on the
    Jacobian ``jac`` of those columns, updated by Broyden's rule after each accepted step and
    never by differences. Returns (u, sum of squares, the Jacobian carried on)."""
    u = np.asarray(u0, dtype=float).copy()
    free = list(free)
    r = fun(u)
    chi = float(r @ r)
    jac = np.array(jac, dtype=float)
    if not free:
        return u, chi, jac
    damping = 0.0
    for _ in range(MAX_PROFILE_STEP_EVALUATIONS - 1):
        normal = jac.T @ jac
        step = -np.linalg.solve(normal + damping * np.diag(np.diag(normal))
                                + RIDGE * np.eye(len(free)), jac.T @ r)
        trial = u.copy()
        trial[free] = np.clip(u[free] + step, 0.0, 1.0)
        dx = trial[free] - u[free]
        predicted = chi - float(np.sum((r + jac @ dx) ** 2))
        if predicted < PROFILE_CHI2_TOL:
            if np.allclose(dx, step):
                break
            # The cube cut the step short of the linearisation's minimum and the cut one gains
            # nothing: a damped step is shorter and may stay inside.
            damping = _more_damping(damping)
            continue
        r_trial = fun(trial)
        chi_trial = float(r_trial @ r_trial)
        if chi_trial < chi:
            if float(np.max(np.abs(dx))) >= FD_STEP_UNIT:
                jac += np.outer(r_trial - r - jac @ dx, dx) / float(dx @ dx)
            gained = chi - chi_trial
            u, r, chi = trial, r_trial, chi_trial
            damping /= DAMPING_FACTOR
            if gained < PROFILE_CHI2_TOL:
                break
        else:
            damping = _more_damping(damping)
    return u, chi, jac


def _more_damping(damping: float) -> float:
    return FIRST_DAMPING if damping < FIRST_DAMPING else damping * DAMPING_FACTOR


def latin_starts(dim: int, starts: int, seed: int) -> list[NDArray[np.float64]]:
    from scipy.stats import qmc

    return list(qmc.LatinHypercube(d=dim, seed=seed).random(starts))


def multistart(fun: _Counted, dim: int, starts: int, descents: int, seed: int,
               extra: Sequence[ArrayLike] = ()) -> tuple[NDArray[np.float64], float]:
    """The lowest of local descents from the ``descents`` lowest of ``starts`` Latin-hypercube
    points over the cube (and ``extra`` points, say the start values)."""
    points = [np.asarray(p, dtype=float) for p in extra] + latin_starts(dim, starts, seed)
    chis = [float(np.sum(r ** 2)) for r in fun.many(points)]
    best_u, best_chi = points[int(np.argmin(chis))], float(min(chis))
    for i in np.argsort(chis)[:descents]:
        u, chi, _ = local_minimum(fun, points[int(i)], range(dim))
        if chi < best_chi:
            best_u, best_chi = u, chi
    return best_u, best_chi


def first_steps(jac: NDArray[np.float64]) -> NDArray[np.float64]:
    """Each parameter's first profile step from the local curvature (J^T J, ridged)."""
    p = jac.shape[1]
    cov = np.linalg.inv(jac.T @ jac + RIDGE * np.eye(p))
    half = math.sqrt(CHI2_95) * np.sqrt(np.clip(np.diag(cov), 0.0, None))
    return np.clip(FIRST_STEP_SHARE * half, MIN_STEP, MAX_STEP)


def _crossing(t0: float, rise0: float, t1: float, rise1: float) -> float:
    """Where the rise reaches CHI2_95 between two profile steps, by linear interpolation of
    its square root (exact for a quadratic misfit, whose root rise is linear in the step)."""
    s0, s1, target = math.sqrt(max(rise0, 0.0)), math.sqrt(max(rise1, 0.0)), math.sqrt(CHI2_95)
    if s1 <= s0:
        return t1
    return t0 + (target - s0) * (t1 - t0) / (s1 - s0)


def profile(fun: _Counted, u_opt: NDArray[np.float64], chi_opt: float, j: int,
            first_step: float, jac: NDArray[np.float64]) -> ProfileInterval:
    """The 95 % interval of parameter ``j``: step it away from ``u_opt`` either way, the others
    re-minimised at each step, until the sum of squares rises by :data:`CHI2_95`
    (interpolated, then one step taken there and interpolated again) or the range ends.

    ``jac`` is the residuals' Jacobian at ``u_opt``. Each step starts the others where its
    linearisation puts their minimum (the last step's optimum moved along the valley's
    direction) and re-minimises them on its columns, carried from step to step
    (:func:`carried_minimum`)."""
    dim = u_opt.size
    others = [k for k in range(dim) if k != j]
    # How the others' minimum moves per unit of u_j, to first order.
    valley = -np.asarray(np.linalg.lstsq(jac[:, others], jac[:, j], rcond=None)[0],
                         dtype=float)
    ends, bounded, points, complete = [], [], [], True
    for side in (-1.0, 1.0):
        t_prev, rise_prev, u_prev, jac_prev = 0.0, 0.0, u_opt.copy(), jac[:, others]
        t, end, at_bound = first_step, None, False
        try:
            for _ in range(MAX_PROFILE_STEPS):
                target = min(max(u_opt[j] + side * t, 0.0), 1.0)
                t = abs(target - u_opt[j])
                u, chi, jac_step = carried_minimum(fun, _along(u_prev, j, target, valley),
                                                   others, jac_prev)
                points.append((target, chi))
                rise = chi - chi_opt
                if rise >= CHI2_95:
                    t_cross = _crossing(t_prev, rise_prev, t, rise)
                    # One more step where the interpolation puts the crossing, and the bracket
                    # it falls in interpolated again: exact for a quadratic, close for a valley
                    # that bends.
                    at = u_opt[j] + side * t_cross
                    _, chi_c, _ = carried_minimum(fun, _along(u_prev, j, at, valley),
                                                  others, jac_prev)
                    points.append((float(at), chi_c))
                    rise_c = chi_c - chi_opt
                    if rise_c >= CHI2_95:
                        t_cross = _crossing(t_prev, rise_prev, t_cross, rise_c)
                    else:
                        t_cross = _crossing(t_cross, rise_c, t, rise)
                    end = u_opt[j] + side * t_cross
                    break
                if target in (0.0, 1.0):
                    end, at_bound = target, True
                    break
                t_prev, rise_prev, u_prev, jac_prev = t, rise, u, jac_step
                t = next_step(t, rise)
        except CostLimitError:
            complete = False
        if end is None:  # out of steps or of budget: as far as it got, and not determined
            end = min(max(u_opt[j] + side * t_prev, 0.0), 1.0)
            complete = False
        ends.append(float(end))
        bounded.append(at_bound)
    return ProfileInterval(j, ends[0], ends[1], bounded[0], bounded[1], complete,
                           tuple(sorted(points)))


def next_step(t: float, rise: float) -> float:
    """The profile's next step after one of ``t`` whose sum of squares rose by ``rise``
    (below :data:`CHI2_95`): :data:`OVERSHOOT` times where a quadratic misfit would cross,
    ``t sqrt(CHI2_95 / rise)``, kept within [:data:`MIN_GROWTH`, :data:`MAX_GROWTH`] times
    ``t``; a rise at or below zero (the misfit's jitter) takes the longest."""
    if rise <= 0.0:
        return MAX_GROWTH * t
    aimed = OVERSHOOT * t * math.sqrt(CHI2_95 / rise)
    return min(max(aimed, MIN_GROWTH * t), MAX_GROWTH * t)


def _along(u: NDArray[np.float64], j: int, u_j: float, valley: NDArray[np.float64]
           ) -> NDArray[np.float64]:
    """``u`` with coordinate ``j`` set to ``u_j`` and the others moved along ``valley`` (their
    change per unit of ``u_j``) by as much, kept in the cube."""
    others = [k for k in range(u.size) if k != j]
    start = u.copy()
    start[others] = np.clip(start[others] + valley * (u_j - u[j]), 0.0, 1.0)
    start[j] = u_j
    return start


def search_minimum(residuals: Residuals, dim: int, start: ArrayLike | None = None,
                   starts: int = 8, descents: int = 2, seed: int = 0,
                   max_evaluations: int = 400) -> tuple[NDArray[np.float64], float, int]:
    """The multi-start of :func:`fit_profiles` alone: (lowest point, its sum of squares,
    evaluations). The cost limit ends the search at the lowest point seen so far."""
    fun = _Counted(residuals, max_evaluations)
    extra = [] if start is None else [np.asarray(start, dtype=float)]
    try:
        u, chi = multistart(fun, dim, starts, descents, seed, extra)
    except CostLimitError:
        u, chi = fun.lowest()
    return u, chi, fun.evaluations


class _Subspace:
    """The residuals over the ``free`` coordinates of a point, the others held at ``base``."""

    def __init__(self, fun: Residuals, base: ArrayLike, free: Sequence[int]) -> None:
        self.fun = fun
        self.base = np.asarray(base, dtype=float)
        self.free = list(free)

    def full(self, x: ArrayLike) -> NDArray[np.float64]:
        u = self.base.copy()
        u[self.free] = x
        return u

    def __call__(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        return self.fun(self.full(x))

    def many(self, points: Sequence[ArrayLike]) -> list[NDArray[np.float64]]:
        return _batch(self.fun, [self.full(x) for x in points])


def _batch(fun: Residuals, points: Sequence[NDArray[np.float64]]) -> list[NDArray[np.float64]]:
    batch = getattr(fun, 'many', None)
    return list(batch(points)) if batch is not None else [fun(u) for u in points]


def seen_coordinates(residuals: Residuals, u: ArrayLike) -> tuple[int, ...]:
    """The coordinates ``residuals`` see about ``u`` (:data:`SEEN_STEP_UNIT`,
    :data:`SEEN_RESIDUAL`), each shifted towards the cube's inside; the points come as one
    batch."""
    u = np.asarray(u, dtype=float)
    points, _ = _shifted(u, SEEN_STEP_UNIT)
    r0, *rs = _batch(residuals, [u, *points])
    return tuple(j for j, r in enumerate(rs)
                 if float(np.max(np.abs(np.asarray(r) - r0), initial=0.0)) >= SEEN_RESIDUAL)


def search_coordinates(residuals: Residuals, base: ArrayLike, free: Sequence[int],
                       starts_per_coordinate: int = 3, descents: int = 2, seed: int = 0,
                       max_evaluations: int = 400) -> tuple[NDArray[np.float64], float, int]:
    """:func:`search_minimum` over the ``free`` coordinates of ``base`` (the point is also a
    start), the others held: (the whole lowest point, its sum of squares, evaluations)."""
    sub = _Subspace(residuals, base, free)
    if not sub.free:
        return sub.base, float(np.sum(residuals(sub.base) ** 2)), 1
    x, chi, evaluations = search_minimum(
        sub, len(sub.free), sub.base[sub.free], starts=starts_per_coordinate * len(sub.free),
        descents=descents, seed=seed, max_evaluations=max_evaluations)
    return sub.full(x), chi, evaluations


def region_draws(residuals: Residuals, u: ArrayLike, free: Sequence[int], count: int,
                 seed: int = 0, limit: int = 400) -> list[NDArray[np.float64]]:
    """``count`` points drawn about ``u``, a minimum of ``residuals`` over the ``free``
    coordinates, from the linearised posterior those residuals give them (mean ``u``,
    covariance (J^T J)^-1 of a difference Jacobian there, Latin-hypercube normal draws), the
    other coordinates held, each kept in the cube. For starts where another misfit has steps
    that this one's region spans: which kick lands on which branch changes within the
    thresholds' 95 % region, and a descent stays on the side of a step it starts on.
    At most ``limit`` evaluations (the Jacobian's, ``len(free)`` beside ``u``'s)."""
    from scipy.stats import norm

    u = np.asarray(u, dtype=float)
    free = list(free)
    if not free or count <= 0:
        return []
    sub = _Subspace(residuals, u, free)
    jac = _jacobian(_Counted(sub, limit), u[free])
    # The covariance's square root, by its eigenvectors: the draws' spread along each of the
    # region's axes is that axis's own, however the parameters correlate.
    values, vectors = np.linalg.eigh(np.linalg.inv(jac.T @ jac + RIDGE * np.eye(len(free))))
    root = vectors * np.sqrt(np.clip(values, 0.0, None))
    uniform = np.clip(np.array(latin_starts(len(free), count, seed)), 1e-9, 1.0 - 1e-9)
    draws = []
    for z in norm.ppf(uniform):
        point = u.copy()
        point[free] = np.clip(u[free] + root @ z, 0.0, 1.0)
        draws.append(point)
    return draws


def fit_profiles(residuals: Residuals, dim: int, start: ArrayLike | None = None,
                 starts: int = 8, descents: int = 2, seed: int = 0,
                 max_evaluations: int = 400,
                 extra_starts: Sequence[ArrayLike] = (), polish: bool = False) -> ProfileFit:
    """Global minimum of ``sum(residuals(u)**2)`` over the unit cube by multi-start, then each
    coordinate's 95 % profile interval.

    Parameters
    ----------
    residuals : callable
        u (shape (dim,), in [0, 1]) -> residual vector, each in units of its standard deviation.
    start : array, optional
        A point the search also starts from (the start values).
    extra_starts : sequence of arrays
        Further points the search starts from (another fit's optimum, say).
    polish : bool
        The lowest point of the search (with ``descents`` 0: the lowest start) goes on by
        Levenberg-Marquardt on a difference Jacobian carried by Broyden's rule
        (:func:`carried_minimum`), a fresh one each time the carried one stops
        (:data:`POLISH_ROUNDS`), and so does a restart: for starts a search has already
        brought near the optimum, where a descent by least squares takes a difference
        Jacobian at every step (the shipped example's six parameters: the search and such a
        descent left the profiles nearly none of the cost limit's 300 evaluations; polished,
        the profiles had some 280).
    starts, descents, seed
        Latin-hypercube points over the cube, and descents from the lowest of them.
    max_evaluations : int
        The cost limit: distinct points evaluated, search and profiles together. A profile the
        limit stops is reported incomplete (so undetermined), the search's best point so far
        is kept.

    Where a profile finds a point :data:`LOWER_BY` lower than the optimum, the search missed
    that basin: the descent starts again from the lowest point seen and the profiles are read
    about its end, at most :data:`PROFILE_RESTARTS` times (``lower_found`` says one still
    went lower).
    """
    fun = _Counted(residuals, max_evaluations)
    extra = ([] if start is None else [np.asarray(start, dtype=float)]) + [
        np.asarray(p, dtype=float) for p in extra_starts]
    try:
        u_opt, chi_opt = multistart(fun, dim, starts, descents, seed, extra)
        if polish:
            u_opt, chi_opt = _polished(fun, u_opt)
    except CostLimitError:
        u_opt, chi_opt = fun.lowest()
        return ProfileFit(u_opt, chi_opt, tuple(
            ProfileInterval(j, 0.0, 1.0, True, True, False, ()) for j in range(dim)),
            fun.evaluations, True, False)
    for restart in range(PROFILE_RESTARTS + 1):
        intervals = _profiles(fun, u_opt, chi_opt)
        u_low, chi_low = fun.lowest()
        if chi_low >= chi_opt - LOWER_BY or restart == PROFILE_RESTARTS:
            break
        try:
            u_new, chi_new = (_polished(fun, u_low) if polish else
                              local_minimum(fun, u_low, range(dim))[:2])
        except CostLimitError:  # the intervals about the optimum before, said to be so
            break
        u_opt, chi_opt = (u_new, chi_new) if chi_new <= chi_low else (u_low, chi_low)
    return ProfileFit(u_opt, chi_opt, intervals, fun.evaluations,
                      not all(i.complete for i in intervals), chi_low < chi_opt - LOWER_BY)


def _polished(fun: _Counted, u: NDArray[np.float64]) -> tuple[NDArray[np.float64], float]:
    """Rounds of :func:`carried_minimum` from ``u``, each on a fresh difference Jacobian,
    until one lowers the sum of squares by less than :data:`LOWER_BY` (less than a profile
    restarts for) or after :data:`POLISH_ROUNDS`."""
    chi = fun.chi2(u)
    for _ in range(POLISH_ROUNDS):
        u_new, chi_new, _ = carried_minimum(fun, u, range(u.size), _jacobian(fun, u))
        gained = chi - chi_new
        u, chi = u_new, chi_new
        if gained < LOWER_BY:
            break
    return u, chi


def _profiles(fun: _Counted, u_opt: NDArray[np.float64],
              chi_opt: float) -> tuple[ProfileInterval, ...]:
    """Each coordinate's profile interval about ``u_opt``, first steps from its Jacobian."""
    try:
        jac = _jacobian(fun, u_opt)
    except CostLimitError:
        jac = np.zeros((fun(u_opt).size, u_opt.size))
    steps = first_steps(jac)
    return tuple(profile(fun, u_opt, chi_opt, j, float(steps[j]), jac)
                 for j in range(u_opt.size))


def _jacobian(fun: _Counted, u: NDArray[np.float64]) -> NDArray[np.float64]:
    """Forward differences of :data:`FD_STEP_UNIT` (backward at the range's top); a column
    whose step moved one residual by more than :data:`SHEET_RESIDUAL` is taken the other way
    too, and the smaller of the two kept."""
    points, steps = _shifted(u, FD_STEP_UNIT)
    r0, *rs = fun.many([u, *points])
    columns = [(r - r0) / h for r, h in zip(rs, steps, strict=True)]
    suspect = [j for j, h in enumerate(steps)
               if float(np.max(np.abs(columns[j] * h), initial=0.0)) > SHEET_RESIDUAL
               and 0.0 <= u[j] - h <= 1.0]
    other_points = [u.copy() for _ in suspect]
    for point, j in zip(other_points, suspect, strict=True):
        point[j] -= steps[j]
    for j, r in zip(suspect, fun.many(other_points), strict=True):
        other = (r - r0) / -steps[j]
        if float(np.linalg.norm(other)) < float(np.linalg.norm(columns[j])):
            columns[j] = other
    return np.column_stack(columns)


def _shifted(u: NDArray[np.float64], step: float) -> tuple[list[NDArray[np.float64]],
                                                          list[float]]:
    """``u`` with each coordinate in turn moved by ``step`` (by ``-step`` where that would
    leave the cube), and the steps taken."""
    points, steps = [], []
    for j in range(u.size):
        h = step if u[j] + step <= 1.0 else -step
        shifted = u.copy()
        shifted[j] += h
        points.append(shifted)
        steps.append(h)
    return points, steps
