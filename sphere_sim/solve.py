"""Time integration of an assembled model through a voltage programme.

Integration restarts at every voltage edge, so no step straddles a discontinuity of the input.
The solver does no I/O; it returns a :class:`Trajectory` with a :class:`SolverStatus` and
counters.
"""

import dataclasses
import enum
import itertools
import time

import numpy as np
from scipy.integrate import solve_ivp

from sphere_sim.programme import PulseProgramme

# Characteristic magnitudes of each kind of state: atol = rtol * scale, and the scaled error
# of the benchmarks divides by the same numbers.
SCALE_BEAM_Z_M = 1e-6
SCALE_BEAM_PHI_RAD = 1e-3
SCALE_BEAM_ZDOT_M_PER_S = 1e-2
SCALE_BEAM_PHIDOT_RAD_PER_S = 10.0
SCALE_SPHERE_POS_M = 1e-6
SCALE_QUAT = 1e-4
SCALE_SPHERE_VEL_M_PER_S = 1e-3
SCALE_SPHERE_OMEGA_RAD_PER_S = 0.1


IMPLICIT_METHODS = ('Radau', 'BDF', 'LSODA')


class SolverStatus(enum.Enum):
    SUCCESS = 'success'
    FAILED = 'failed'
    BUDGET_EXCEEDED = 'budget_exceeded'


class SolverError(RuntimeError):
    """The integration could not proceed; carries the time and state where it stopped."""

    def __init__(self, message, t_s=None, state=None, status=SolverStatus.FAILED):
        super().__init__(message)
        self.t_s = t_s
        self.state = state
        self.status = status


@dataclasses.dataclass
class SolverStats:
    nfev: int = 0
    njev: int = 0
    nlu: int = 0
    n_segments: int = 0
    wall_time_s: float = 0.0


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


def state_scale(model):
    """Per-state characteristic magnitudes, shape (n_states,)."""
    n = model.n_beams
    scale = np.empty(model.n_states)
    scale[0:2 * n:2] = SCALE_BEAM_Z_M
    scale[1:2 * n:2] = SCALE_BEAM_PHI_RAD
    scale[2 * n:4 * n:2] = SCALE_BEAM_ZDOT_M_PER_S
    scale[2 * n + 1:4 * n:2] = SCALE_BEAM_PHIDOT_RAD_PER_S
    if model.has_sphere:
        o = model.sphere_offset
        scale[o:o + 3] = SCALE_SPHERE_POS_M
        scale[o + 3:o + 7] = SCALE_QUAT
        scale[o + 7:o + 10] = SCALE_SPHERE_VEL_M_PER_S
        scale[o + 10:o + 13] = SCALE_SPHERE_OMEGA_RAD_PER_S
    return scale


def segment_times(programme, t_start_s, t_end_s):
    """Boundaries of the constant-voltage segments inside [t_start_s, t_end_s]."""
    inner = [t for t in programme.edges() if t_start_s < t < t_end_s]
    return [t_start_s, *inner, t_end_s]


def simulate(model, x0, t_end_s, programme=None, rtol=1e-6, atol=None, method='Radau',
             sample_period_s=1e-4, t_start_s=0.0, max_wall_s=None):
    """Integrate ``model`` from ``x0`` to ``t_end_s`` under a pulse programme.

    Parameters
    ----------
    model : Model
    x0 : ndarray, shape (n_states,)
    t_end_s : float
    programme : PulseProgramme, optional
        Defaults to the scene's programme.
    rtol : float
    atol : float or ndarray, optional
        Defaults to ``rtol * state_scale(model)``.
    method : str
        A scipy ``solve_ivp`` method.
    sample_period_s : float
        Output sampling; every segment boundary is sampled too.
    max_wall_s : float, optional
        Wall-clock budget; exceeding it raises :class:`SolverError` (BUDGET_EXCEEDED).

    Returns
    -------
    Trajectory
    """
    programme = model.scene.programme if programme is None else programme
    if not isinstance(programme, PulseProgramme):
        raise TypeError('programme must be a PulseProgramme')
    atol = rtol * state_scale(model) if atol is None else atol
    stats = SolverStats()
    started = time.perf_counter()
    x = np.array(x0, dtype=float)
    ts, xs, us = [np.array([t_start_s])], [x[:, None]], []
    bounds = segment_times(programme, t_start_s, t_end_s)
    deadline = None if max_wall_s is None else started + max_wall_s
    for t0, t1 in itertools.pairwise(bounds):
        u = programme.voltages_at(t0, model.beams)
        n_samples = max(1, int(np.ceil((t1 - t0) / sample_period_s)))
        t_eval = np.linspace(t0, t1, n_samples + 1)[1:]

        def fun(t, y, u=u):
            if deadline is not None and time.perf_counter() > deadline:
                raise SolverError(f'wall-clock budget of {max_wall_s} s exceeded', t, y,
                                  SolverStatus.BUDGET_EXCEEDED)
            return model.rhs(t, y, u)

        def jac(t, y, u=u):
            return model.jacobian(t, y, u)

        options = {'jac': jac} if method in IMPLICIT_METHODS else {}
        sol = solve_ivp(fun, (t0, t1), x, method=method, rtol=rtol, atol=atol, t_eval=t_eval,
                        **options)
        stats.nfev += sol.nfev
        stats.njev += sol.njev
        stats.nlu += sol.nlu
        stats.n_segments += 1
        if sol.status < 0 or not np.all(np.isfinite(sol.y)):
            raise SolverError(f'{method} failed at t = {sol.t[-1] if sol.t.size else t0} s: '
                              f'{sol.message}', t0, x)
        x = sol.y[:, -1].copy()
        ts.append(sol.t)
        xs.append(sol.y)
        us.append(np.repeat(u[:, None], sol.t.size, axis=1))
    stats.wall_time_s = time.perf_counter() - started
    u_all = np.concatenate([programme.voltages_at(t_start_s, model.beams)[:, None], *us], axis=1)
    return Trajectory(model, np.concatenate(ts), np.concatenate(xs, axis=1), u_all,
                      SolverStatus.SUCCESS, stats)
