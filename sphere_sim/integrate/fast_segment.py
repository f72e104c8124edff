"""The compiled method's segment driver: the Radau IIA of :mod:`radau_compiled`, chunk by chunk.

Integrates one :class:`~sphere_sim.integrate.segment.Segment` and is listed in
:data:`sphere_sim.integrate.solve.SEGMENT_METHODS` as ``fast``, beside the library methods'
drivers (:mod:`sphere_sim.integrate.library_segments`). The compiled loop returns to Python
every ``radau_compiled.CHUNK_STEPS`` accepted steps, where the run's budget is checked
(:func:`run_compiled`, which drives the compiled Rosenbrock W-method's chunks too).
"""

from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from sphere_sim.integrate import radau_compiled as rc
from sphere_sim.integrate.segment import Segment, SolverError, SolverStatus, check_domain
from sphere_sim.model.scaling import state_scale

# Newton contraction rate above which the compiled Radau refreshes its Jacobian: Hairer's
# recommendation (THET = 0.1) when a Jacobian costs many right-hand sides; ours costs n + 1.
FAST_JACOBIAN_RATE = 0.1
# Forward differences of the compiled kernel for the compiled Radau's Jacobian: central ones
# are ~1e4 times more accurate but change neither the steps nor the result, and cost twice as
# much (docs/numerics.md, "Jacobian").
FAST_JACOBIAN_CENTRAL = False


# One chunk of a compiled method: (t, x, h, i_eval, steps left, x_eval, Jacobian scale,
# counters) -> (status, t, x, h, i_eval), with the statuses of radau_compiled.
CompiledChunk = Callable[[float, NDArray[np.float64], float, int, int, NDArray[np.float64],
                          NDArray[np.float64], NDArray[np.int64]],
                         tuple[int, float, NDArray[np.float64], float, int]]


def segment_fast(seg: Segment) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Integrate one constant-voltage segment with the compiled Radau IIA."""
    def chunk(t: float, x: NDArray[np.float64], h: float, i_eval: int, steps_left: int,
              x_eval: NDArray[np.float64], jac_scale: NDArray[np.float64],
              counters: NDArray[np.int64]) -> tuple[int, float, NDArray[np.float64], float, int]:
        return rc.integrate(
            t, seg.t1, x, seg.u, seg.model.kernel_arrays, float(seg.rtol), seg.atol, jac_scale,
            seg.t_eval, x_eval, i_eval, h, np.inf, steps_left, seg.onset_depth_m,
            FAST_JACOBIAN_RATE, FAST_JACOBIAN_CENTRAL, counters)

    return run_compiled(seg, 'fast', chunk)


def run_compiled(seg: Segment, name: str,
                 chunk: CompiledChunk) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Integrate ``seg`` chunk by chunk with a compiled method (``name`` in its errors): the
    run's budget checked between chunks, the compiled counters added to its stats, the
    electrode and the step size's floor turned into the segment's errors."""
    model, t, x, u = seg.model, seg.t0, seg.x, seg.u
    budget, stats = seg.budget, seg.stats
    counters = np.zeros(rc.N_COUNTERS, dtype=np.int64)
    x_eval = np.empty((model.n_states, seg.t_eval.size))
    jac_scale = state_scale(model)
    h, i_eval = -1.0, 0
    x = np.ascontiguousarray(x, dtype=float)
    x_chunk = x
    status = rc.STATUS_CHUNK
    while status == rc.STATUS_CHUNK:
        budget.check(t, x)
        steps_before = int(counters[rc.C_STEPS])
        x_chunk = x
        status, t, x, h, i_eval = chunk(t, x, h, i_eval, max(1, budget.max_steps - budget.steps),
                                        x_eval, jac_scale, counters)
        budget.steps += int(counters[rc.C_STEPS]) - steps_before
        if status == rc.STATUS_STEP_BUDGET:
            budget.steps = max(budget.steps, budget.max_steps + 1)
    stats.nfev += int(counters[rc.C_NFEV])
    stats.njev += int(counters[rc.C_NJEV])
    stats.nlu += int(counters[rc.C_NLU])
    # The compiled methods count all of these (SolverStats).
    assert stats.n_steps is not None and stats.n_rejected is not None
    assert stats.n_newton_failed is not None and stats.n_onset_bounded is not None
    stats.n_steps += int(counters[rc.C_STEPS])
    stats.n_rejected += int(counters[rc.C_REJECTED])
    stats.n_onset_restarts += int(counters[rc.C_ONSET_REJECTED])
    stats.n_newton_failed += int(counters[rc.C_NEWTON_FAILED])
    stats.n_onset_bounded += int(counters[rc.C_ONSET_PREDICTED])
    budget.check(t, x)
    if status == rc.STATUS_LEFT_DOMAIN:
        check_domain(model, t, x, u, model.electrode_gaps(x_chunk))
    if status == rc.STATUS_STEP_TOO_SMALL or not np.all(np.isfinite(x)):
        raise SolverError(f'{name}: step size fell below 10 ulp of t at t = {t} s '
                          f'(h = {h:.3g} s)', t, x, SolverStatus.STEP_TOO_SMALL)
    return x, x_eval[:, :i_eval]
