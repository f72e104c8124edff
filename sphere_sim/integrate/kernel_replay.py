"""What a solver's evaluations of the model cost without the solver.

A library method drives the compiled kernels from Python; how much of its time is the
kernels' own is the floor any compiled version of that method would meet. ``RecordingModel``
records every state a solver evaluates the model at, and ``replay_wall_s`` evaluates the
kernels at those states again in compiled loops, with nothing of the solver around them.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from sphere_sim.model import dynamics as dyn
from sphere_sim.model.scaling import state_scale

if TYPE_CHECKING:
    from sphere_sim.model.assembly import Model

    # A RecordingModel stands in for a Model wherever one is taken (it forwards every attribute
    # to the wrapped model); this tells the type checker so.
    _ModelStandIn = Model
else:
    _ModelStandIn = object

# One recorded evaluation: (t_s, x, u_v).
Call = tuple[float, NDArray[np.float64], NDArray[np.float64]]


class RecordingModel(_ModelStandIn):
    """A model whose solver functions (:meth:`Model.at_voltages`) record their arguments.

    Everything else is the wrapped model's. ``rhs_calls`` and ``jac_calls`` list
    ``(t_s, x, u_v)`` of every evaluation, with copies of the state, so that
    ``len(rhs_calls)`` is the solver's nfev and ``len(jac_calls)`` its njev.
    """

    def __init__(self, model: Model) -> None:
        self.model = model
        self.rhs_calls: list[Call] = []
        self.jac_calls: list[Call] = []

    def __getattr__(self, name: str) -> Any:
        return getattr(self.model, name)

    def at_voltages(self, u: ArrayLike) -> tuple[
            Callable[..., NDArray[np.float64]],
            Callable[[float, NDArray[np.float64]], NDArray[np.float64]]]:
        fun, jac = self.model.at_voltages(u)
        u_v = np.array(u, dtype=float)

        def recording_fun(t: float, x: NDArray[np.float64],
                          out: NDArray[np.float64] | None = None) -> NDArray[np.float64]:
            self.rhs_calls.append((t, x.copy(), u_v))
            return fun(t, x, out)

        def recording_jac(t: float, x: NDArray[np.float64]) -> NDArray[np.float64]:
            self.jac_calls.append((t, x.copy(), u_v))
            return jac(t, x)

        return recording_fun, recording_jac


# A compiled kernel: numba reads its types from the arguments.
@numba.njit(cache=True)
def _replay_rhs(  # type: ignore[no-untyped-def]
        t, x, u, p, flags, directions, rbf_cz, rbf_cphi, rbf_w, out):
    """dx/dt at each recorded state into ``out``, shape (n_calls, n_states)."""
    diag = np.empty(dyn.N_DIAG)
    for i in range(t.size):
        dyn.rhs_kernel(t[i], x[i], u[i], p, flags, directions, rbf_cz, rbf_cphi, rbf_w, out[i],
                       diag)


# A compiled kernel: numba reads its types from the arguments.
@numba.njit(cache=True)
def _replay_jacobian(  # type: ignore[no-untyped-def]
        t, x, u, p, flags, directions, rbf_cz, rbf_cphi, rbf_w, scale, out):
    """The Jacobian at each recorded state into ``out``, shape (n_calls, n_states, n_states)."""
    for i in range(t.size):
        dyn.jacobian_kernel(t[i], x[i], u[i], p, flags, directions, rbf_cz, rbf_cphi, rbf_w,
                            scale, out[i])


def replay(model: Model, calls: Sequence[Call],
           jacobian: bool = False) -> tuple[NDArray[np.float64], float]:
    """Evaluate the right-hand side (or the Jacobian) of ``model`` at recorded ``calls``.

    Returns
    -------
    values : ndarray, shape (n_calls, n_states) or (n_calls, n_states, n_states)
        dx/dt, or d(dx/dt)/dx, at each call, as the solver received them.
    wall_s : float
        Wall time of the compiled loop alone (s).
    """
    n = model.n_states
    t = np.array([c[0] for c in calls], dtype=float)
    x = np.array([c[1] for c in calls], dtype=float).reshape(len(calls), n)
    u = np.array([c[2] for c in calls], dtype=float).reshape(len(calls), model.n_beams)
    loop: Callable[..., None]
    args: tuple[NDArray[Any], ...] = (t, x, u, model.p, model.flags, model.beam_directions,
                                      model.rbf_cz, model.rbf_cphi, model.rbf_w)
    if jacobian:
        values = np.empty((len(calls), n, n))
        loop, args = _replay_jacobian, (*args, state_scale(model), values)
    else:
        values = np.empty((len(calls), n))
        loop, args = _replay_rhs, (*args, values)
    started = time.perf_counter()
    loop(*args)
    return values, time.perf_counter() - started


def replay_wall_s(model: Model, recording: RecordingModel, repeats: int) -> float:
    """Fastest of ``repeats`` compiled replays of everything ``recording`` holds (s): the
    recorded solver's kernel evaluations alone."""
    parts = [(calls, jacobian) for calls, jacobian in
             ((recording.rhs_calls, False), (recording.jac_calls, True)) if calls]
    if not parts:
        # The compiled 'fast' method evaluates the kernels inside its own loop, not through
        # at_voltages: a zero here would read as a floor of nothing.
        raise ValueError('nothing was recorded: only solvers that evaluate the model through '
                         'Model.at_voltages (the library methods) can be replayed')
    for calls, jacobian in parts:
        replay(model, calls[:1], jacobian)  # compiles, so that no timed loop includes it
    best = np.inf
    for _ in range(repeats):
        wall_s = sum(replay(model, calls, jacobian)[1] for calls, jacobian in parts)
        best = min(best, wall_s)
    return best
