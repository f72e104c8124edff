"""The Rosenbrock W-method's segment driver: :mod:`rosenbrock_compiled`, chunk by chunk.

Listed in :data:`sphere_sim.integrate.solve.SEGMENT_METHODS` as ``rosenbrock``. As
:mod:`~sphere_sim.integrate.fast_segment` does for the compiled Radau, it returns to Python
every ``CHUNK_STEPS`` accepted steps to check the run's budget, and adds the compiled counters
to the run's :class:`~sphere_sim.integrate.segment.SolverStats` (``n_newton_failed`` counts
stage sweeps lost to a non-finite stage or a failed factorisation; ``n_onset_bounded`` stays 0:
the onset rule here only rejects).
"""

import numpy as np
from numpy.typing import NDArray

from sphere_sim.integrate import radau_compiled as rc
from sphere_sim.integrate import rosenbrock_compiled as ros
from sphere_sim.integrate.segment import Segment, SolverError, SolverStatus, check_domain
from sphere_sim.model.scaling import state_scale


def segment_rosenbrock(seg: Segment) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Integrate one constant-voltage segment with the compiled ROS34PW2."""
    model, x, t0, t1, u = seg.model, seg.x, seg.t0, seg.t1, seg.u
    budget, stats = seg.budget, seg.stats
    counters = np.zeros(rc.N_COUNTERS, dtype=np.int64)
    x_eval = np.empty((model.n_states, seg.t_eval.size))
    jac_scale = state_scale(model)
    t, h, i_eval = t0, -1.0, 0
    x = np.ascontiguousarray(x, dtype=float)
    x_chunk = x
    status = ros.STATUS_CHUNK
    while status == ros.STATUS_CHUNK:
        budget.check(t, x)
        steps_before = int(counters[rc.C_STEPS])
        x_chunk = x
        status, t, x, h, i_eval = ros.integrate(
            t, t1, x, u, model.kernel_arrays, float(seg.rtol), seg.atol, jac_scale, seg.t_eval,
            x_eval, i_eval, h, np.inf, max(1, budget.max_steps - budget.steps),
            seg.onset_depth_m, counters)
        budget.steps += int(counters[rc.C_STEPS]) - steps_before
        if status == ros.STATUS_STEP_BUDGET:
            budget.steps = max(budget.steps, budget.max_steps + 1)
    stats.nfev += int(counters[rc.C_NFEV])
    stats.njev += int(counters[rc.C_NJEV])
    stats.nlu += int(counters[rc.C_NLU])
    assert stats.n_steps is not None and stats.n_rejected is not None
    assert stats.n_newton_failed is not None and stats.n_onset_bounded is not None
    stats.n_steps += int(counters[rc.C_STEPS])
    stats.n_rejected += int(counters[rc.C_REJECTED])
    stats.n_onset_restarts += int(counters[rc.C_ONSET_REJECTED])
    stats.n_newton_failed += int(counters[rc.C_NEWTON_FAILED])
    stats.n_onset_bounded += int(counters[rc.C_ONSET_PREDICTED])
    budget.check(t, x)
    if status == ros.STATUS_LEFT_DOMAIN:
        check_domain(model, t, x, u, model.electrode_gaps(x_chunk))
    if status == ros.STATUS_STEP_TOO_SMALL or not np.all(np.isfinite(x)):
        raise SolverError(f'rosenbrock: step size fell below 10 ulp of t at t = {t} s '
                          f'(h = {h:.3g} s)', t, x, SolverStatus.STEP_TOO_SMALL)
    return x, x_eval[:, :i_eval]
