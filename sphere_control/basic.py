"""The basic controller of §4.2: full kicks in the direction nearest to the error, eq. (58).

It rests while the error angle Phi is below the resting band Phi_min. (The paper's sentence
says "only when Phi is smaller than Phi_min", which contradicts its own purpose and Fig. 13;
kicking happens when Phi is at least Phi_min.)
"""

import dataclasses

import numpy as np
from numpy.typing import NDArray

from sphere_control.command import Command, KickBelief, unit_xy
from sphere_control.geometry import error_angle_rad, error_direction_rad, nearest_action
from sphere_sim.kicks.discrete import DIAGONAL_DIRECTIONS_RAD

FULL_INTENSITY = 1.0  # the basic controller always kicks with the optimised full inputs


@dataclasses.dataclass(frozen=True)
class BasicParams:
    """Parameters of the basic controller.

    Attributes
    ----------
    phi_min_rad : float
        Resting band Phi_min (rad): no kick while the error angle is below it.
    full_width_rad : float
        The model's rotation width of a full kick (rad); only used to predict a kick's effect
        (state estimation), not for the decision.
    directions_rad : tuple of float
        The model's kick directions sigma_a (rad), one per action.
    """

    phi_min_rad: float
    full_width_rad: float = 0.0
    directions_rad: tuple[float, ...] = DIAGONAL_DIRECTIONS_RAD


class BasicController:
    """Eq. (58) with the resting band; not adaptive."""

    def __init__(self, params: BasicParams) -> None:
        self.params = params

    def decide(self, normal: NDArray[np.float64],
               reference: NDArray[np.float64]) -> Command | None:
        if error_angle_rad(normal, reference) < self.params.phi_min_rad:
            return None
        theta = error_direction_rad(normal, reference)
        return Command(nearest_action(theta, self.params.directions_rad), FULL_INTENSITY)

    def observe(self, normal_before: NDArray[np.float64], command: Command,
                normal_after: NDArray[np.float64]) -> None:
        return None

    def expected_displacement_xy(self, normal: NDArray[np.float64],
                                 command: Command) -> NDArray[np.float64]:
        return (self.params.full_width_rad * command.intensity
                * unit_xy(self.params.directions_rad[command.action]))

    def believed_kicks(self) -> KickBelief:
        directions = np.array(self.params.directions_rad, dtype=float)
        return KickBelief(directions, np.full(directions.shape, self.params.full_width_rad),
                          learned=False)
