"""The full model run beside the live twin, kick by kick: how far the twin's landings are from it.

The live twin integrates at the live tolerance, or looks its kicks up in a table; either is a rung
of the ladder (:mod:`sphere_sim.twin.ladder`), with an error measured on a fixed kick set. The check
measures it on the kicks the twin actually served: each programme the plant starts is handed, with
the state it started from, to a process of its own, which runs the full model at a tolerance within
the live budget; when both landings are in, their angle joins the running divergence.

The check never holds the twin up: a kick whose reference is not done yet waits in ``pending``,
and one that arrives while ``MAX_PENDING`` wait is counted as skipped, not queued.
"""

from __future__ import annotations

import concurrent.futures
import dataclasses
import math
import multiprocessing
import statistics

import numpy as np
from numpy.typing import NDArray

from sphere_sim.integrate.solve import simulate
from sphere_sim.integrate.tolerances import CHECK_RTOL
from sphere_sim.kicks.design import KICK_RELAXATION, cardan_of_normal
from sphere_sim.model.assembly import Model
from sphere_sim.model.initial_state import rest_state
from sphere_sim.model.programme import PulseProgramme
from sphere_sim.model.rotations import angle_between

# Kicks whose reference may be under way or waiting at once; beyond that a kick is skipped (the
# check runs on one spare core and may be slower than the twin).
MAX_PENDING = 8


def reference_normals(model: Model, x_start: NDArray[np.float64] | None,
                      normal_start: NDArray[np.float64], programme: PulseProgramme,
                      window_s: float, period_s: float) -> NDArray[np.float64]:
    """The full model's surface normal at each of the twin's samples over ``window_s`` of
    ``programme`` (shape (3, n + 1), the start first), from ``x_start`` (a state of ``model``),
    or from rest at ``normal_start`` where the twin holds no state (the table).

    Integrated sample by sample, as the twin's continuous plant is, so that a kick a later
    programme cuts short is compared at the sample where it was cut.
    """
    x = (rest_state(model, cardan_of_normal(normal_start), relaxation=KICK_RELAXATION)
         if x_start is None else np.array(x_start, dtype=float))
    normals = [model.surface_normal(x)]
    for k in range(1, math.ceil(window_s / period_s - 1e-9) + 1):
        t_end_s = min(k * period_s, window_s)
        traj = simulate(model, x, t_end_s, programme, rtol=CHECK_RTOL,
                        sample_period_s=t_end_s - (k - 1) * period_s,
                        t_start_s=(k - 1) * period_s)
        x = traj.final_state
        normals.append(model.surface_normal(x))
    return np.stack(normals, axis=1)


@dataclasses.dataclass
class _Kick:
    start_s: float
    reference: concurrent.futures.Future[NDArray[np.float64]]
    landed_s: float | None = None  # the end of its window, or the next programme's start
    live: NDArray[np.float64] | None = None

    def land(self, time_s: float, normal: NDArray[np.float64]) -> None:
        self.landed_s = time_s
        self.live = np.array(normal, dtype=float)

    def error_rad(self, period_s: float) -> float:
        assert self.landed_s is not None and self.live is not None
        normals = self.reference.result()
        i = min(normals.shape[1] - 1, round((self.landed_s - self.start_s) / period_s))
        return angle_between(normals[:, i], self.live)


@dataclasses.dataclass(frozen=True)
class Divergence:
    """The running divergence of the twin's landings from the full model's (rad)."""

    checked: int
    pending: int
    skipped: int
    median_rad: float
    max_rad: float


class FidelityCheck:
    """Runs the full model beside a live twin, one process, and compares the landings.

    Parameters
    ----------
    model : Model
        The full model (with every mechanism the scene declares).
    window_s : float
        A kick lands this long after its programme starts.
    period_s : float
        The twin's sample period: programmes start, and kicks land, on its grid.
    executor : concurrent.futures.Executor, optional
        Where the references run; a one-process pool by default (closed by :meth:`close`).
    """

    def __init__(self, model: Model, window_s: float, period_s: float,
                 executor: concurrent.futures.Executor | None = None) -> None:
        self.model = model
        self.window_s = window_s
        self.period_s = period_s
        self._own = executor is None
        # A fresh interpreter, not a fork: the twin's process runs DDS threads a fork would copy
        # in whatever state they are.
        self._executor = executor or concurrent.futures.ProcessPoolExecutor(
            max_workers=1, mp_context=multiprocessing.get_context('forkserver'))
        self._kicks: list[_Kick] = []
        self._errors: list[float] = []
        self.skipped = 0

    def started(self, time_s: float, x_start: NDArray[np.float64] | None,
                normal_start: NDArray[np.float64], programme: PulseProgramme) -> None:
        """A programme started at ``time_s`` from ``x_start`` (None: from rest at
        ``normal_start``, the twin's normal then). A kick still in flight lands here: the new
        programme cuts it short, and the two are compared where it was cut."""
        self.observe(time_s, normal_start, cut=True)
        if len(self._kicks) >= MAX_PENDING:
            self.skipped += 1
            return
        # A state of another rung's layout says nothing the full model can start from.
        state = (np.array(x_start, dtype=float)
                 if x_start is not None and x_start.size == self.model.n_states else None)
        future = self._executor.submit(reference_normals, self.model, state,
                                       np.array(normal_start, dtype=float), programme,
                                       self.window_s, self.period_s)
        self._kicks.append(_Kick(time_s, future))

    def observe(self, time_s: float, normal: NDArray[np.float64], cut: bool = False) -> None:
        """The twin's normal at ``time_s``: the landing of every kick whose window is over (of
        every kick in flight, with ``cut``)."""
        for kick in self._kicks:
            if kick.live is None and (cut or time_s >= kick.start_s + self.window_s - 1e-12):
                kick.land(time_s, normal)
        self._collect()

    def _collect(self) -> None:
        waiting = []
        for kick in self._kicks:
            if kick.live is not None and kick.reference.done():
                self._errors.append(kick.error_rad(self.period_s))
            else:
                waiting.append(kick)
        self._kicks = waiting

    def divergence(self) -> Divergence:
        """The divergence so far (NaNs before the first kick is checked)."""
        self._collect()
        errors = self._errors
        return Divergence(len(errors), len(self._kicks), self.skipped,
                          statistics.median(errors) if errors else float('nan'),
                          max(errors) if errors else float('nan'))

    def close(self, wait: bool = False) -> Divergence:
        """Stop the check; with ``wait``, after the references under way are done. Returns the
        divergence it ends with."""
        if wait:
            for kick in self._kicks:
                if kick.live is not None:
                    kick.reference.result()
        result = self.divergence()
        if self._own:
            self._executor.shutdown(wait=wait, cancel_futures=True)
        return result
