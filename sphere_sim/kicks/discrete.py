"""The discrete kick model x_{t+1} = f(x_t, a_t, u_K) of §4, as an interface.

A *kick plant* maps the sphere's resting surface normal, an action (a kick direction) and an
intensity u_K in [0, 1] to the next resting normal. The lookup table built from the continuous
model, the continuous model itself and the synthetic plants of the tests all implement it, so
controllers never know which one they drive.
"""

import dataclasses
import math
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from msg_defs.device import KICK_WINDOW_S

# The four diagonal kicks of the paper: hind-left kick -> normal moves towards -45 deg, and its
# rotations by 90 deg (Fig. 7). Angles are polar angles of the normal's x-y displacement.
DIAGONAL_DIRECTIONS_RAD = tuple(math.radians(a) for a in (-45.0, 45.0, 135.0, -135.0))
# With the axis-parallel kicks of §6, eight directions.
EIGHT_DIRECTIONS_RAD = tuple(math.radians(a) for a in (-45.0, 0.0, 45.0, 90.0, 135.0, 180.0,
                                                      -135.0, -90.0))
CONE_HALF_ANGLE_RAD = math.radians(40.0)  # the state space investigated in the paper
# The paper's optimised hind-left kick, sqrt(alpha^2 + beta^2) (§4.1, Fig. 5 and Fig. 6a).
PAPER_FULL_KICK_RAD = math.radians(0.54)
# The noise study's sensor noise: a tenth of the paper's full kick, per axis (9.4e-4 rad).
NOISE_STUDY_STD_RAD = 0.1 * PAPER_FULL_KICK_RAD
# A kick period is a kick's settle time rounded up to this: the offline loop's decision grid,
# and a whole number of samples of a 100 Hz sensor.
KICK_PERIOD_STEP_S = 0.01
LEVEL_NORMAL = np.array([0.0, 0.0, 1.0])  # "we initialize the sphere to start with zero angles"


@dataclasses.dataclass(frozen=True)
class KickResult:
    """Outcome of one kick.

    Attributes
    ----------
    normal : ndarray, shape (3,)
        Resting unit surface normal after the kick settles.
    peak_deviation_rad : float
        Largest angle between the transient normal and the final one (the overshoot of §6).
    settle_time_s : float
        Time until the normal stays within the settling band of its final value.
    """

    normal: NDArray[np.float64]
    peak_deviation_rad: float = 0.0
    settle_time_s: float = 0.0


class KickPlant(Protocol):
    """What a controller may ask of the device: the kick directions it offers and a kick.

    Every kick model implements it: the lookup table, the continuous model, the twin's plant,
    the analytic and perturbed plants of the studies, and their calibrated wrappers. A kick
    model that also says how each kick is driven (its design and pulse programme) is a
    :class:`~sphere_sim.kicks.lookup_table.ProgrammedKickPlant`.
    """

    @property
    def directions_rad(self) -> tuple[float, ...]:
        """Nominal direction (rad, polar angle of the normal's x-y displacement) of each
        action; its length is the number of actions."""

    def kick(self, normal: NDArray[np.float64], action: int, intensity: float) -> KickResult:
        """Apply kick ``action`` (index into ``directions_rad``) of intensity in [0, 1].

        Parameters
        ----------
        normal : ndarray, shape (3,)
            Current resting unit surface normal.
        action : int
        intensity : float

        Returns
        -------
        KickResult
        """


def normal_from_xy(x_sn: float, y_sn: float) -> NDArray[np.float64]:
    """Unit normal with the given x and y components (eq. 53), z >= 0."""
    z2 = 1.0 - x_sn * x_sn - y_sn * y_sn
    if z2 < 0.0:
        raise ValueError(f'({x_sn}, {y_sn}) is not the x-y part of a unit vector')
    return np.array([x_sn, y_sn, math.sqrt(z2)])


def normal_from_cardan(alpha_deg: float, beta_deg: float = 0.0) -> NDArray[np.float64]:
    """Surface normal of Cardan angles (alpha, beta, 0) in degrees (eq. A1, 53)."""
    a, b = math.radians(alpha_deg), math.radians(beta_deg)
    return np.array([math.sin(b), -math.sin(a) * math.cos(b), math.cos(a) * math.cos(b)])




def settled_kick_period_s(settle_time_s: float) -> float:
    """The shortest decision period after which a kick that settles in ``settle_time_s`` is
    over: rounded up to KICK_PERIOD_STEP_S; the kick window when no settle time is known."""
    if not (math.isfinite(settle_time_s) and settle_time_s > 0.0):
        return KICK_WINDOW_S
    return round(math.ceil(settle_time_s / KICK_PERIOD_STEP_S - 1e-9) * KICK_PERIOD_STEP_S, 9)


def kick_period_s(kick_plant: KickPlant) -> float:
    """The kick period of a kick plant: the settle time of its full first kick from the level
    state, rounded up (:func:`settled_kick_period_s`). The offline loop decides at this
    period, the controller node waits this long after a kick's reported start, and the discrete
    twin lands its kicks after it, so all three describe the same cycle."""
    return settled_kick_period_s(float(kick_plant.kick(LEVEL_NORMAL, 0, 1.0).settle_time_s))
