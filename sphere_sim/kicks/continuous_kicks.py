"""The continuous model of §3 as a kick model: one kick simulated from rest per call.

Describes the same kick as a lookup table built from the same spec (the outcome is the normal
at the end of the kick window), so that a closed loop can run on either.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from sphere_sim.kicks.characteristics import KickBench
from sphere_sim.kicks.design import simulate_kick
from sphere_sim.kicks.discrete import KickResult

if TYPE_CHECKING:
    from sphere_sim.kicks.lookup_table import TableSpec
    from sphere_sim.model.parameters import ParameterSet


class ContinuousKickPlant:
    """The continuous model of §3 as a KickPlant: one simulated kick per call.

    The sphere starts each kick at rest at the given normal; the outcome is the normal at the
    end of the kick window, as in the lookup table, so both discrete models describe the same
    kick.

    Parameters
    ----------
    spec : sphere_sim.kicks.lookup_table.TableSpec
        The table's kick: its reference (hind-left) design, turned a quarter turns for action
        a, and its voltage offsets.
    params : ParameterSet, optional
        The default set unless given.
    """

    def __init__(self, spec: TableSpec, params: ParameterSet | None = None) -> None:
        self.spec = spec
        self.bench = KickBench(params)
        self.directions_rad = tuple(spec.design.direction_rad + q * 0.5 * math.pi
                                    for q in range(4))

    def kick(self, normal: NDArray[np.float64], action: int, intensity: float) -> KickResult:
        normal = np.asarray(normal, dtype=float)
        rest = self.bench.rest(normal)
        kicked, _ = simulate_kick(self.bench.model, normal,
                                  self.spec.programme(action, float(intensity), normal),
                                  window_s=self.bench.window_s, rtol=self.bench.rtol,
                                  x_rest=rest)
        return kicked
