"""The extended controller of §4.2 (Figs. 9, 11, 12): learned kick directions and widths.

Per action a it keeps a direction sigma_a and a rotation-width network h_a(u_K). A step picks
the action whose sigma_a is closest to the error direction Theta (eq. 58 on the learned
directions), finds the point of that action's kick line closest to the reference (Fig. 11), the
rotation Psi* to it, and the intensity u_K* = h_a^-1(Psi*). After the kick, the achieved
direction and width update sigma_a (eq. 61) and h_a (eqs. 62-63) at Table A1's learning rates.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterable
from typing import TypeVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

from sphere_control.command import Command, Controller, KickBelief, unit_xy
from sphere_control.geometry import (
    displacement_xy,
    error_angle_rad,
    error_direction_rad,
    nearest_action,
    target_rotation_rad,
    wrap_angle_rad,
)
from sphere_control.rotation_network import NetworkShape, RotationWidthNetwork
from sphere_sim.kicks.discrete import DIAGONAL_DIRECTIONS_RAD, KickPlant
from sphere_sim.model.rotations import angle_between

# The controller prelearn teaches and hands back.
C = TypeVar('C', bound=Controller)


@dataclasses.dataclass(frozen=True)
class LearningRates:
    """Table A1."""

    direction: float = 0.9  # alpha_sigma
    bias: float = 0.1  # alpha_b
    weights: float = 0.1  # alpha_w


@dataclasses.dataclass(frozen=True)
class ExtendedParams:
    """Parameters of the extended controller.

    Attributes
    ----------
    phi_min_rad : float
        Resting band Phi_min (rad).
    full_width_rad : float
        The model's rotation width of a full kick (rad): the prior h_a(u) = full_width * u.
    directions_rad : tuple of float
        The model's kick directions, the initial sigma_a (rad).
    shape : NetworkShape
    rates : LearningRates
    direction_learning_min_rad : float
        Kicks shorter than this (rad) do not update sigma_a. 0 (the default) learns from every
        kick that moved the sphere, as the paper does; a kick model whose programmes can slip
        the sphere in a direction of their own sets it to the longest such slip
        (:func:`sphere_control.controllers.direction_learning_floor_rad`).
    """

    phi_min_rad: float
    full_width_rad: float
    directions_rad: tuple[float, ...] = DIAGONAL_DIRECTIONS_RAD
    shape: NetworkShape = dataclasses.field(default_factory=NetworkShape)
    rates: LearningRates = dataclasses.field(default_factory=LearningRates)
    direction_learning_min_rad: float = 0.0


class ExtendedController:
    """Adaptive directions and rotation widths (the gray part of Fig. 9)."""

    def __init__(self, params: ExtendedParams) -> None:
        self.params = params
        self.directions_rad = np.array(params.directions_rad, dtype=float)
        self.networks = [RotationWidthNetwork.linear(params.full_width_rad, params.shape)
                         for _ in params.directions_rad]

    def copy(self) -> ExtendedController:
        """An independent controller with the same learned state (e.g. after pre-learning)."""
        other = ExtendedController(self.params)
        other.directions_rad = self.directions_rad.copy()
        other.networks = [net.copy() for net in self.networks]
        return other

    def decide(self, normal: NDArray[np.float64],
               reference: NDArray[np.float64]) -> Command | None:
        if error_angle_rad(normal, reference) < self.params.phi_min_rad:
            return None
        action = nearest_action(error_direction_rad(normal, reference), self.directions_rad)
        psi_star = target_rotation_rad(normal, self.directions_rad[action], reference)
        return Command(action, self.networks[action].inverse(psi_star))

    def observe(self, normal_before: NDArray[np.float64], command: Command,
                normal_after: NDArray[np.float64]) -> None:
        """Eqs. (61)-(63) from the measured normals before and after the kick.

        The achieved width Psi~ is the rotation angle times the cosine between the achieved
        and the (updated) learned direction: the signed progress along the kick line, which
        goes negative when a kick moves the normal backwards (Fig. 10's negative widths).
        """
        a = command.action
        d = displacement_xy(normal_before, normal_after)
        rates = self.params.rates
        rotation = angle_between(normal_before, normal_after)
        # Only a kick longer than the floor teaches a direction (one that did not move the
        # sphere has none, whatever the floor).
        if rotation > self.params.direction_learning_min_rad:
            achieved = math.atan2(d[1], d[0])
            gap = wrap_angle_rad(self.directions_rad[a] - achieved)
            self.directions_rad[a] = wrap_angle_rad(self.directions_rad[a] - rates.direction * gap)
        length = math.hypot(*d)
        along = float(d @ unit_xy(self.directions_rad[a])) / length if length > 0.0 else 0.0
        self.networks[a].update(command.intensity, rotation * along, rates.bias, rates.weights)

    def expected_displacement_xy(self, normal: NDArray[np.float64],
                                 command: Command) -> NDArray[np.float64]:
        a = command.action
        return self.networks[a](command.intensity) * unit_xy(self.directions_rad[a])

    def believed_kicks(self) -> KickBelief:
        return KickBelief(self.directions_rad.copy(),
                          np.array([net(1.0) for net in self.networks]), learned=True)

    def direction_errors_rad(self, true_directions_rad: Iterable[float]) -> NDArray[np.float64]:
        """|sigma_a - true direction| per action (rad), shape (n_actions,)."""
        return np.array([abs(wrap_angle_rad(s - t)) for s, t in
                         zip(self.directions_rad, true_directions_rad, strict=True)])


def prelearn(controller: C, plant: KickPlant, start_normal: ArrayLike, n_kicks: int,
             seed: int) -> C:
    """Pre-learning phase: kicks of every action in turn at random intensities.

    Cycling through the actions keeps the sphere near ``start_normal`` while each network sees
    its whole intensity range. The controller learns in place; the plant's state is not kept
    (the evaluation starts again from its own initial normal).

    Parameters
    ----------
    controller : ExtendedController
    plant : KickPlant
    start_normal : ndarray, shape (3,)
    n_kicks : int
    seed : int
        Seed of the random intensities.

    Returns
    -------
    ExtendedController
        The same controller, for chaining.
    """
    rng = np.random.default_rng(seed)
    normal = np.asarray(start_normal, dtype=float)
    n_actions = len(plant.directions_rad)
    for k in range(n_kicks):
        command = Command(k % n_actions, float(rng.uniform(0.0, 1.0)))
        after = plant.kick(normal, command.action, command.intensity).normal
        controller.observe(normal, command, after)
        normal = after
    return controller
