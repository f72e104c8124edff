"""The device's symmetry group D4: quarter turns and mirrors of beams, states and kicks (Fig. 7).

An element ``Symmetry(quarter_turns, mirrored)`` first mirrors at the x-z plane (y -> -y) if
``mirrored``, then turns counter-clockwise (top view, y up) by ``quarter_turns`` x 90 deg. It
permutes the beams, maps horizontal vectors and surface normals, pulse programmes and full
model states, so one simulated kick stands for its seven images.
"""

import dataclasses
import itertools
import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from sphere_sim.model.assembly import Model
from sphere_sim.model.programme import PulseProgramme
from sphere_sim.model.rotations import matrix_to_quat, quat_to_matrix

BEAMS = (1, 2, 3, 4)


def beam_position_angle_rad(beam: int) -> float:
    """Polar angle of a beam's suspension: beam 1 left (180 deg), then clockwise."""
    return math.pi - (beam - 1) * 0.5 * math.pi


@dataclasses.dataclass(frozen=True)
class Symmetry:
    quarter_turns: int = 0
    mirrored: bool = False

    @property
    def matrix(self) -> NDArray[np.float64]:
        """The 3x3 orthogonal map of inertial vectors."""
        c = round(math.cos(0.5 * math.pi * self.quarter_turns))
        s = round(math.sin(0.5 * math.pi * self.quarter_turns))
        turn = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        mirror = np.diag([1.0, -1.0 if self.mirrored else 1.0, 1.0])
        return turn @ mirror

    @property
    def determinant(self) -> float:
        return -1.0 if self.mirrored else 1.0

    def inverse(self) -> 'Symmetry':
        if self.mirrored:
            return self  # a mirror followed by a turn is itself a reflection: an involution
        return Symmetry((-self.quarter_turns) % 4, False)

    def beam_map(self) -> dict[int, int]:
        """Dict beam -> image beam."""
        G = self.matrix[:2, :2]
        out = {}
        for beam in BEAMS:
            angle = beam_position_angle_rad(beam)
            image = G @ np.array([math.cos(angle), math.sin(angle)])
            image_angle = math.atan2(image[1], image[0])
            out[beam] = min(BEAMS, key=lambda b: abs(math.remainder(
                beam_position_angle_rad(b) - image_angle, 2 * math.pi)))
        return out

    def apply_vector(self, v: ArrayLike) -> NDArray[np.float64]:
        """Image of inertial vectors, shape (3,) or (3, n)."""
        return self.matrix @ np.asarray(v, dtype=float)

    def apply_direction(self, angle_rad: float) -> float:
        """Image of a polar angle in the x-y plane."""
        G = self.matrix[:2, :2]
        image = G @ np.array([math.cos(angle_rad), math.sin(angle_rad)])
        return math.atan2(image[1], image[0])

    def apply_programme(self, programme: PulseProgramme) -> PulseProgramme:
        return programme.mirrored(self.beam_map())

    def apply_state(self, model: Model, x: NDArray[np.float64]) -> NDArray[np.float64]:
        """Image of a full model state (all four beams present)."""
        if tuple(model.beams) != BEAMS:
            raise ValueError('state symmetry needs all four beams in order')
        y = np.array(x, dtype=float)
        mapping = self.beam_map()
        n = model.n_beams
        for beam, image in mapping.items():
            i, j = beam - 1, image - 1
            y[2 * j:2 * j + 2] = x[2 * i:2 * i + 2]
            y[2 * n + 2 * j:2 * n + 2 * j + 2] = x[2 * n + 2 * i:2 * n + 2 * i + 2]
        if model.has_sphere:
            o = model.sphere_offset
            G = self.matrix
            R = quat_to_matrix(np.ascontiguousarray(x[o + 3:o + 7]))
            y[o:o + 3] = G @ x[o:o + 3]
            y[o + 3:o + 7] = matrix_to_quat(G @ R @ G.T)
            y[o + 7:o + 10] = G @ x[o + 7:o + 10]
            y[o + 10:o + 13] = self.determinant * (G @ x[o + 10:o + 13])
        if model.has_bristles:
            # A tip's bristle deflection is an inertial vector that goes with its beam.
            b = model.bristle_offset
            for beam, image in mapping.items():
                i, j = beam - 1, image - 1
                y[b + 3 * j:b + 3 * j + 3] = G @ x[b + 3 * i:b + 3 * i + 3]
        return y


def all_symmetries() -> tuple[Symmetry, ...]:
    return tuple(Symmetry(q, m) for m, q in itertools.product((False, True), range(4)))


def kick_axis_mirror(direction_rad: float) -> Symmetry:
    """The mirror at the line through the centre along ``direction_rad`` (a multiple of 45 deg).

    A mirror at the x axis followed by q quarter turns is the mirror at the line at q x 45 deg.
    """
    eighths = 4.0 * direction_rad / math.pi
    if abs(eighths - round(eighths)) > 1e-9:
        raise ValueError(f'a kick axis of the device lies at a multiple of 45 deg, got '
                         f'{math.degrees(direction_rad)} deg')
    return Symmetry(round(eighths) % 4, True)


# The mirror at the line y = -x (the hind-left kick's own axis): it swaps beams 1<->2 and 3<->4.
KICK_AXIS_MIRROR = kick_axis_mirror(-0.25 * math.pi)
