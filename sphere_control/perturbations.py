"""Model mismatch and measurement noise for evaluating controllers (§5.1, §5.2, §6).

:class:`PerturbedPlant` wraps any KickPlant and turns and scales each kick's x-y displacement,
so the device no longer kicks where the controller's model says; :class:`NoisySensor` adds
seeded Gaussian noise to the measured normal.
"""

import dataclasses
import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from sphere_sim.kicks.discrete import KickPlant, KickResult, normal_from_xy

# Measured normals are kept strictly inside the unit disc so they stay unit vectors.
MAX_MEASURED_XY_RADIUS = 0.999999


@dataclasses.dataclass(frozen=True)
class Mismatch:
    """How the device differs from the model.

    Attributes
    ----------
    direction_offset_rad : float
        Every kick's displacement turned counter-clockwise by this (rad); the paper uses 12 deg
        (Fig. 14) and 33 deg (Fig. 15).
    width_scale : float
        Every kick's displacement scaled by this (1: as modelled).
    """

    direction_offset_rad: float = 0.0
    width_scale: float = 1.0


class PerturbedPlant:
    """A KickPlant whose kicks are those of ``base`` turned and scaled by ``mismatch``.

    ``directions_rad`` stays the base plant's (what the controller believes); the true
    directions are :attr:`true_directions_rad`.
    """

    def __init__(self, base: KickPlant, mismatch: Mismatch) -> None:
        self.base = base
        self.mismatch = mismatch
        self.directions_rad = tuple(base.directions_rad)

    @property
    def true_directions_rad(self) -> tuple[float, ...]:
        return tuple(d + self.mismatch.direction_offset_rad for d in self.directions_rad)

    def kick(self, normal: NDArray[np.float64], action: int, intensity: float) -> KickResult:
        result = self.base.kick(normal, action, intensity)
        d = result.normal[:2] - np.asarray(normal, dtype=float)[:2]
        c = math.cos(self.mismatch.direction_offset_rad)
        s = math.sin(self.mismatch.direction_offset_rad)
        turned = self.mismatch.width_scale * np.array([c * d[0] - s * d[1], s * d[0] + c * d[1]])
        xy = np.asarray(normal, dtype=float)[:2] + turned
        return KickResult(normal_from_xy(*xy), result.peak_deviation_rad, result.settle_time_s)


class NoisySensor:
    """Measured normal = true normal with N(0, std^2) added to x and y, then made unit again.

    Parameters
    ----------
    std_rad : float
        Standard deviation of each x-y component (about rad for the tilts here).
    seed : int
    """

    def __init__(self, std_rad: float, seed: int) -> None:
        self.std_rad = float(std_rad)
        self.rng = np.random.default_rng(seed)

    def measure(self, normal: ArrayLike) -> NDArray[np.float64]:
        """A noisy unit normal, shape (3,)."""
        xy = np.asarray(normal, dtype=float)[:2] + self.rng.normal(0.0, self.std_rad, 2)
        radius = math.hypot(*xy)
        if radius > MAX_MEASURED_XY_RADIUS:
            xy *= MAX_MEASURED_XY_RADIUS / radius
        return normal_from_xy(*xy)
