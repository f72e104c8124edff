"""The Rosenbrock W-method's segment driver: :mod:`rosenbrock_compiled`, chunk by chunk.

Listed in :data:`sphere_sim.integrate.solve.SEGMENT_METHODS` as ``rosenbrock``. Driven by
:func:`~sphere_sim.integrate.fast_segment.run_compiled`, as the compiled Radau is, it returns
to Python every ``CHUNK_STEPS`` accepted steps to check the run's budget, and adds the compiled
counters to the run's :class:`~sphere_sim.integrate.segment.SolverStats` (``n_newton_failed`` counts
stage sweeps lost to a non-finite stage or a failed factorisation; ``n_onset_bounded`` stays 0:
the onset rule here only rejects).
"""

import numpy as np
from numpy.typing import NDArray

from sphere_sim.integrate import rosenbrock_compiled as ros
from sphere_sim.integrate.fast_segment import run_compiled
from sphere_sim.integrate.segment import Segment


def segment_rosenbrock(seg: Segment) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Integrate one constant-voltage segment with the compiled ROS34PW2."""
    def chunk(t: float, x: NDArray[np.float64], h: float, i_eval: int, steps_left: int,
              x_eval: NDArray[np.float64], jac_scale: NDArray[np.float64],
              counters: NDArray[np.int64]) -> tuple[int, float, NDArray[np.float64], float, int]:
        return ros.integrate(
            t, seg.t1, x, seg.u, seg.model.kernel_arrays, float(seg.rtol), seg.atol, jac_scale,
            seg.t_eval, x_eval, i_eval, h, np.inf, steps_left, seg.onset_depth_m, counters)

    return run_compiled(seg, 'rosenbrock', chunk)
