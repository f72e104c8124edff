"""Plants the simulator node can run: anything with ``step(dt_s, voltages_v) -> normal``.

The node only needs to advance a plant by a time step under the beam voltages held over that
step and read the mirror's surface normal back, so that is the whole interface; the physics
model plugs in behind it without the node changing.
"""

from typing import Protocol

import numpy as np

BEAM_COUNT = 4
# The flattened face points straight up when the sphere rests on the four beam tips.
RESTING_NORMAL = np.array([0.0, 0.0, 1.0])


class Plant(Protocol):
    """What the simulator node drives."""

    def step(self, dt_s: float, voltages_v: np.ndarray) -> np.ndarray:
        """Advance by ``dt_s`` (s) with ``voltages_v`` (V, shape (4,)) held on beams 1..4.

        Returns the unit surface normal in the world frame, shape (3,), afterwards.
        """
        ...


class RestingPlant:
    """Placeholder plant: the sphere at rest, whatever the voltages.

    Validates its inputs like a real plant would, so the node's wiring is exercised, and
    keeps the simulated time so callers can check that it advances.

    Attributes
    ----------
    time_s : float
        Simulated time (s), the sum of the steps taken.
    """

    def __init__(self):
        self.time_s = 0.0

    def step(self, dt_s, voltages_v):
        """Advance by ``dt_s`` (s); returns the resting normal ``[0, 0, 1]``.

        Raises
        ------
        ValueError
            If ``dt_s`` is not a positive finite number or ``voltages_v`` is not 4 finite
            values.
        """
        if not (np.isfinite(dt_s) and dt_s > 0):
            raise ValueError(f'dt_s must be a positive finite number, got {dt_s}')
        voltages = np.asarray(voltages_v, dtype=float)
        if voltages.shape != (BEAM_COUNT,) or not np.all(np.isfinite(voltages)):
            raise ValueError(f'voltages_v must be {BEAM_COUNT} finite values, got {voltages_v}')
        self.time_s += dt_s
        return RESTING_NORMAL.copy()
