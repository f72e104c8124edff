"""What a segment method is given and may report: one constant-voltage segment of a run.

:func:`~sphere_sim.integrate.solve.simulate` hands each segment method a :class:`Segment`; the
method draws on the run's :class:`Budget`, adds its work to the run's :class:`SolverStats` and
ends the run with a :class:`SolverError` (:func:`check_domain` raises one when the model's
domain is left).
"""

import dataclasses
import enum
import time

import numpy as np
from numpy.typing import NDArray

from sphere_sim.model import gaps as gap_kernels
from sphere_sim.model.assembly import Model


class SolverStatus(enum.Enum):
    SUCCESS = 'success'
    FAILED = 'failed'
    BUDGET_EXCEEDED = 'budget_exceeded'
    STEP_TOO_SMALL = 'step_too_small'
    LEFT_MODEL_DOMAIN = 'left_model_domain'


class SolverError(RuntimeError):
    """The integration could not proceed; carries the time and state where it stopped."""

    def __init__(self, message: str, t_s: float | None = None,
                 state: NDArray[np.float64] | None = None,
                 status: SolverStatus = SolverStatus.FAILED) -> None:
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


def check_domain(model: Model, t: float, x: NDArray[np.float64], u: NDArray[np.float64],
                 gaps_start: NDArray[np.float64]) -> None:
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


class Budget:
    """Wall-clock deadline and accepted-step allowance shared by all segments of a run."""

    def __init__(self, max_wall_s: float | None, max_steps: int) -> None:
        self.started = time.perf_counter()
        self.max_wall_s = max_wall_s
        self.deadline = None if max_wall_s is None else self.started + max_wall_s
        self.max_steps = max_steps
        self.steps = 0

    def check(self, t: float, x: NDArray[np.float64]) -> None:
        if self.deadline is not None and time.perf_counter() > self.deadline:
            raise SolverError(f'wall-clock budget of {self.max_wall_s} s exceeded at t = {t} s',
                              t, np.array(x), SolverStatus.BUDGET_EXCEEDED)
        if self.steps > self.max_steps:
            raise SolverError(f'step budget of {self.max_steps} steps exceeded at t = {t} s',
                              t, np.array(x), SolverStatus.BUDGET_EXCEEDED)


@dataclasses.dataclass(frozen=True)
class Segment:
    """One constant-voltage segment of a run, as a segment method integrates it.

    From state ``x`` at ``t0`` to ``t1`` (s) at the beam voltages ``u`` (V), with tolerances
    ``rtol`` and ``atol`` (one per state), sampled at ``t_eval`` (the last is ``t1``), stopping
    at contact onsets deeper than ``onset_depth_m`` (0: no check). ``budget`` and ``stats`` are
    the run's, shared by its segments.
    """

    model: Model
    x: NDArray[np.float64]
    t0: float
    t1: float
    u: NDArray[np.float64]
    rtol: float
    atol: NDArray[np.float64]
    t_eval: NDArray[np.float64]
    onset_depth_m: float
    budget: Budget
    stats: SolverStats
