"""Time integration of an assembled model through a voltage programme.

One entry point, ``simulate(model, x0, t_end_s, programme, rtol, atol, method, ...)``: an
assembled model (started from its scene's initial state if ``x0`` is None), an end time, a
programme, tolerances and a method name. It cuts the run into constant-voltage segments and
hands each, as a :class:`~sphere_sim.integrate.segment.Segment`, to the method's entry in
:data:`SEGMENT_METHODS`.

Methods (docs/numerics.md compares them):

==========  ==================================================================================
fast        the compiled Radau IIA of :mod:`~sphere_sim.integrate.radau_compiled` (the default)
rosenbrock  the compiled Rosenbrock W-method ROS34PW2 of
            :mod:`~sphere_sim.integrate.rosenbrock_compiled` (order 3, no Newton iteration)
Radau       scipy's Radau IIA, BDF, LSODA and the explicit DOP853, stepped one step at a time
BDF         from Python on the same compiled right-hand side and Jacobian
LSODA
DOP853
odeint      the same Fortran LSODA through ``scipy.integrate.odeint``: its step loop runs in
            Fortran and calls back only for the right-hand side and the Jacobian
CVODE       SUNDIALS CVODE (BDF, dense direct solver) through scikit-sundae
==========  ==================================================================================

Every method restarts at each voltage edge of the programme, so no step straddles a jump of
the input, and none steps over a contact onset: a contact open at the start of a step may not
close deeper than ``onset_depth_m`` within it. The compiled method checks every stage of every
step and rejects such a step; the library methods
(:mod:`~sphere_sim.integrate.library_segments`) stop at the onset and restart there.
Each run is bounded by a wall-clock and a step budget and ends either with a
:class:`Trajectory` or with a :class:`SolverError` that says where and why it stopped.
"""

import dataclasses
import functools
import itertools
import math
import time
from collections.abc import Callable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from sphere_sim.integrate import fast_segment, library_segments, rosenbrock_segment
from sphere_sim.integrate.segment import (
    Budget,
    Segment,
    SolverError,
    SolverStats,
    SolverStatus,
)
from sphere_sim.integrate.tolerances import DEFAULT_RTOL
from sphere_sim.model.assembly import Model
from sphere_sim.model.initial_state import initial_state
from sphere_sim.model.programme import PulseProgramme, VoltageSchedule
from sphere_sim.model.scaling import state_scale

SCIPY_METHODS = ('Radau', 'BDF', 'LSODA', 'odeint', 'DOP853')
DEFAULT_METHOD = 'fast'
# A run of the ~100 ms scenes takes well under a second; ten minutes means it is stuck.
DEFAULT_MAX_WALL_S = 600.0
# Accepted steps per run: the stiffest shipped scenes take ~1e4 steps per simulated 100 ms at
# rtol 1e-8, so 2e7 allows 10 s of simulated time at any tolerance before calling it a stall.
DEFAULT_MAX_STEPS = 20_000_000
# Sampled states a run may hold (t, x and u together, 8 bytes each): 1 GiB, about five minutes
# of a sphere scene at the default 0.1 ms sampling; beyond it the allocation fails or swaps, so
# a longer run is refused before anything is allocated.
MAX_SAMPLE_BYTES = 2**30
# Deepest closure of an open contact within one step, as a fraction of the contact law's
# transition depth 2 C / k_c (100 nm with Table A1): 2 nm, where the contact force is still
# 4e-4 C and starting the contact that late adds ~1e-15 J of elastic energy.
ONSET_DEPTH_FRACTION = 0.02


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

    model: Model
    t: NDArray[np.float64]
    x: NDArray[np.float64]
    u: NDArray[np.float64]
    status: SolverStatus
    stats: SolverStats
    message: str = ''

    @property
    def final_state(self) -> NDArray[np.float64]:
        return self.x[:, -1]

    def surface_normal(self) -> NDArray[np.float64]:
        """Surface normal over time, shape (3, n_times)."""
        return self.model.surface_normal(self.x)


def segment_times(programme: PulseProgramme | VoltageSchedule, t_start_s: float,
                  t_end_s: float) -> list[float]:
    """Boundaries of the constant-voltage segments inside [t_start_s, t_end_s]."""
    inner = [t for t in programme.edges() if t_start_s < t < t_end_s]
    return [t_start_s, *inner, t_end_s]


def default_onset_depth_m(model: Model) -> float:
    """ONSET_DEPTH_FRACTION of the contact's transition depth 2 C / k_c (m)."""
    c = model.params.contact
    return ONSET_DEPTH_FRACTION * 2.0 * c.transition_force_n / c.stiffness_n_per_m


# A segment method integrates one Segment: its end state and its states at seg.t_eval.
SegmentMethod = Callable[[Segment], tuple[NDArray[np.float64], NDArray[np.float64]]]
# The method of each name (docs/numerics.md compares them), the way scipy's solve_ivp keeps
# its METHODS.
SEGMENT_METHODS: dict[str, SegmentMethod] = {
    'fast': fast_segment.segment_fast,
    'rosenbrock': rosenbrock_segment.segment_rosenbrock,
    'Radau': functools.partial(library_segments.segment_scipy, 'Radau'),
    'BDF': functools.partial(library_segments.segment_scipy, 'BDF'),
    'LSODA': functools.partial(library_segments.segment_scipy, 'LSODA'),
    'odeint': library_segments.segment_odeint,
    'DOP853': functools.partial(library_segments.segment_scipy, 'DOP853'),
    'CVODE': library_segments.segment_cvode,
}
METHODS = tuple(SEGMENT_METHODS)


def check_sample_grid(model: Model, duration_s: float, sample_period_s: float) -> None:
    """Raise :class:`SolverError` (FAILED) when a run of ``duration_s`` sampled every
    ``sample_period_s`` would hold more than MAX_SAMPLE_BYTES, naming the longest that fits."""
    if not (math.isfinite(duration_s) and sample_period_s > 0.0):
        raise SolverError(f'cannot sample a run of {duration_s:g} s every {sample_period_s:g} s')
    # Samples overshoot the period's count by one per segment; the edges are few.
    bytes_per_sample = 8 * (1 + model.n_states + model.n_beams)
    samples = duration_s / sample_period_s
    if samples * bytes_per_sample > MAX_SAMPLE_BYTES:
        longest_s = MAX_SAMPLE_BYTES / bytes_per_sample * sample_period_s
        raise SolverError(
            f'a run of {duration_s:g} s sampled every {sample_period_s:g} s would hold '
            f'{samples:.3g} samples ({samples * bytes_per_sample / 2**30:.3g} GiB); the '
            f'duration must be at most {longest_s:.4g} s at this sampling')


def simulate(model: Model, x0: ArrayLike | None, t_end_s: float,
             programme: PulseProgramme | VoltageSchedule | None = None,
             rtol: float = DEFAULT_RTOL, atol: ArrayLike | None = None,
             method: str = DEFAULT_METHOD, sample_period_s: float = 1e-4,
             t_start_s: float = 0.0, max_wall_s: float | None = None,
             max_steps: int | None = None, onset_depth_m: float | None = None) -> Trajectory:
    """Integrate ``model`` from ``x0`` to ``t_end_s`` under a pulse programme.

    Parameters
    ----------
    model : Model
        From :func:`~sphere_sim.model.assembly.assemble`.
    x0 : ndarray, shape (n_states,), or None
        None starts from the scene's initial state.
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
        ``trajectory.stats`` holds steps, rejected steps, nfev, njev, nlu and wall time.

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
    check_sample_grid(model, t_end_s - t_start_s, sample_period_s)
    atol = rtol * state_scale(model) if atol is None else atol
    atol = np.broadcast_to(np.asarray(atol, dtype=float), (model.n_states,)).copy()
    onset = default_onset_depth_m(model) if onset_depth_m is None else float(onset_depth_m)
    budget = Budget(DEFAULT_MAX_WALL_S if max_wall_s is None else max_wall_s,
                    DEFAULT_MAX_STEPS if max_steps is None else max_steps)
    stats = SolverStats(method=method)
    segment_method = SEGMENT_METHODS[method]
    x = np.array(initial_state(model) if x0 is None else x0, dtype=float)
    ts, xs, us = [np.array([t_start_s])], [x[:, None]], []
    bounds = segment_times(programme, t_start_s, t_end_s)
    for t0, t1 in itertools.pairwise(bounds):
        u = programme.voltages_at(t0, model.beams)
        n_samples = max(1, math.ceil((t1 - t0) / sample_period_s))
        t_eval = np.linspace(t0, t1, n_samples + 1)[1:]
        t_eval[-1] = t1
        x, x_eval = segment_method(Segment(model, x, t0, t1, u, rtol, atol, t_eval, onset,
                                           budget, stats))
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
