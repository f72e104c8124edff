"""What a controller decides each step, and the interface every controller offers."""

import dataclasses
from typing import Protocol

import numpy as np
from numpy.typing import NDArray


@dataclasses.dataclass(frozen=True)
class Command:
    """One kick: ``action`` indexes the plant's ``directions_rad``; intensity u_K in [0, 1]."""

    action: int
    intensity: float


@dataclasses.dataclass(frozen=True)
class KickBelief:
    """What a controller believes of its kicks now: each action's direction and full-intensity
    width (rad, shape (n_actions,)), and whether it learns them (the extended controller) or
    holds its model's (the basic one)."""

    directions_rad: NDArray[np.float64]
    full_widths_rad: NDArray[np.float64]
    learned: bool


class Controller(Protocol):
    """A feedback law on the resting surface normal.

    ``decide`` returns a :class:`Command`, or ``None`` to rest (no kick this step). After a
    kick, ``observe`` reports the normal measured before and after it, for learning.
    """

    def decide(self, normal: NDArray[np.float64],
               reference: NDArray[np.float64]) -> Command | None:
        """Command or None, for normal and reference (unit vectors, shape (3,))."""

    def observe(self, normal_before: NDArray[np.float64], command: Command,
                normal_after: NDArray[np.float64]) -> None:
        """Learn from one executed kick (a no-op for non-adaptive controllers)."""

    def expected_displacement_xy(self, normal: NDArray[np.float64],
                                 command: Command) -> NDArray[np.float64]:
        """The controller's own prediction of the kick's x-y displacement, shape (2,)."""

    def believed_kicks(self) -> KickBelief:
        """Its kicks as it believes them now (learned, or its model's)."""


def unit_xy(direction_rad: float) -> NDArray[np.float64]:
    """Unit vector of a polar angle, shape (2,)."""
    return np.array([np.cos(direction_rad), np.sin(direction_rad)])
