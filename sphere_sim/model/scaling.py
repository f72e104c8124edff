"""The characteristic magnitude of each kind of state: the model's natural units.

Tolerances are set against them (atol = rtol * scale), the Jacobian's differences are taken in
them, and the benchmarks' scaled errors divide by them.
"""

from typing import Protocol

import numpy as np
from numpy.typing import NDArray

SCALE_BEAM_Z_M = 1e-6
SCALE_BEAM_PHI_RAD = 1e-3
SCALE_BEAM_ZDOT_M_PER_S = 1e-2
SCALE_BEAM_PHIDOT_RAD_PER_S = 10.0
SCALE_SPHERE_POS_M = 1e-6
SCALE_QUAT = 1e-4
SCALE_SPHERE_VEL_M_PER_S = 1e-3
SCALE_SPHERE_OMEGA_RAD_PER_S = 0.1
# A friction bristle's deflection is a slip of the contact, like a position; against its
# presliding displacement (1 nm) its tolerance would be a thousand times the positions' and make
# a resting sphere take tiny steps on numerical noise. At this scale an error of rtol times it
# is an error in friction force of rtol times about 100 mu_c F_n.
SCALE_BRISTLE_M = 1e-7


class StateLayout(Protocol):
    """Where a model keeps each kind of state (:class:`~sphere_sim.model.assembly.Model`, which
    imports this module, has it)."""

    @property
    def n_beams(self) -> int: ...
    @property
    def n_states(self) -> int: ...
    @property
    def has_sphere(self) -> bool: ...
    @property
    def sphere_offset(self) -> int: ...
    @property
    def has_bristles(self) -> bool: ...
    @property
    def bristle_offset(self) -> int: ...


def state_scale(model: StateLayout) -> NDArray[np.float64]:
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
    if model.has_bristles:
        scale[model.bristle_offset:] = SCALE_BRISTLE_M
    return scale
