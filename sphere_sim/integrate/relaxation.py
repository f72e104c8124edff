"""rest_state's relaxation on the compiled Radau IIA: the reference's method and tolerance,
stepped without Python.

:func:`~sphere_sim.model.initial_state.rest_state` lets the sphere down onto the tips and
relaxes it with its orientation held before Newton polishes the rest. Its reference relaxation
is scipy's Radau at ``RADAU_RELAX_RTOL``, stepped from Python; :func:`compiled_relaxation` is
the same method at the same tolerance in the compiled loop of :mod:`radau_compiled` (with its
contact-onset check), and is what the kick workloads relax with (``KICK_RELAXATION``).
"""

import numpy as np
from numpy.typing import NDArray

from sphere_sim.integrate.fast_segment import segment_fast
from sphere_sim.integrate.segment import Budget, Segment, SolverError, SolverStats
from sphere_sim.integrate.solve import default_onset_depth_m
from sphere_sim.model.assembly import Model
from sphere_sim.model.initial_state import RADAU_RELAX_RTOL, RELAX_TIME_S
from sphere_sim.model.scaling import state_scale

# Accepted steps allowed: this relaxation takes about 3e3 on a tilted sphere of the paper's
# device (scipy's, the reference, 1.1e3: it grows a step after a retry); beyond four times that
# it has stalled (a contact 100 times stiffer) and the reference takes over.
RELAX_MAX_STEPS = 12_000


def compiled_relaxation(model: Model, x: NDArray[np.float64],
                        u: NDArray[np.float64]) -> NDArray[np.float64] | None:
    """The state ``RELAX_TIME_S`` after ``x`` under the voltages ``u`` (V), integrated by the
    compiled Radau IIA at the reference's tolerance; None where it fails (the caller's
    reference relaxation then takes over). ``model`` is the one to relax: with its
    orientation held (:meth:`Model.with_orientation_held`) for a tilted sphere's rest."""
    seg = Segment(model, np.ascontiguousarray(x, dtype=float), 0.0, RELAX_TIME_S,
                  np.ascontiguousarray(u, dtype=float), RADAU_RELAX_RTOL,
                  RADAU_RELAX_RTOL * state_scale(model), np.array([RELAX_TIME_S]),
                  default_onset_depth_m(model), Budget(None, RELAX_MAX_STEPS), SolverStats())
    try:
        _, samples = segment_fast(seg)
    except SolverError:
        return None
    y = samples[:, -1].copy()
    return y if np.all(np.isfinite(y)) else None
