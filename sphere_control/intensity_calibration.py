"""u_K defined through the nominal model's level-state width curve: an actuator calibration.

A kick design's own intensity scales its high pair's voltage between the low pair's (no kick)
and the full kick's (:mod:`sphere_sim.kicks.design`). The width that voltage gives is far from
linear in it: on the calibrated table nothing moves below about u = 0.5 (the high beams do not
pull in), the width jumps there, dips after the jump and rises towards full intensity
(docs/control.md). The extended controller starts from the prior h(u) = W u (eq. (59) before
learning) and its five knots are equally spaced, so on the design's own scale it would ask for
the wrong voltage for every width but the full one, and its network could not learn the bend.

The paper maps the voltage to u_K in [0, 1] without saying how (§4.2). This module makes that map
once from the nominal kick model, as an actuator calibration is made once on a device: a
calibrated intensity u asks for the least design intensity whose kick from the level state is
u W wide, W being the full kick's width (the voltage that needs least is the paper's choice
among several solutions). The controllers, the studies and the controller node all speak in
calibrated intensities; only :class:`CalibratedKicks` turns them into the design's.
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING, Generic, TypeVar

import numpy as np
from numpy.typing import NDArray

from sphere_sim.kicks.discrete import LEVEL_NORMAL, KickPlant, KickResult
from sphere_sim.model.rotations import angle_between

if TYPE_CHECKING:
    from sphere_sim.kicks.lookup_table import ProgrammedKickPlant
    from sphere_sim.model.programme import PulseProgramme

# Design intensities at which the level-state curve is sampled, 0.005 apart: every knot of the
# shipped tables (0.01 apart at their finest) is a sample, so the calibration meets a table at
# its knots and follows its interpolation between them, in 0.3 s.
CURVE_SAMPLES = 201

# The kick model a calibration wraps, and one that also makes programmes.
K = TypeVar('K', bound=KickPlant)
P = TypeVar('P', bound='ProgrammedKickPlant')


@dataclasses.dataclass(frozen=True)
class ActionCurve:
    """One action's level-state width over the design's intensity, made invertible.

    Attributes
    ----------
    design_intensities : ndarray, shape (n,)
        Increasing design intensities where the running maximum of the width rises, and where
        the curve climbs out of a dip across its old maximum.
    widths_rad : ndarray, shape (n,)
        The width reached there (rad), non-decreasing (equal at the two ends of a dip).
    """

    design_intensities: NDArray[np.float64]
    widths_rad: NDArray[np.float64]

    @classmethod
    def measure(cls, kicks: KickPlant, action: int, normal: NDArray[np.float64] = LEVEL_NORMAL,
                samples: int = CURVE_SAMPLES) -> ActionCurve:
        """Sample ``action``'s kick from ``normal`` and keep where its running maximum rises:
        a width first reached at u is never asked of a larger u (least voltage)."""
        normal = np.asarray(normal, dtype=float)
        u = np.linspace(0.0, 1.0, samples)
        width = np.array([angle_between(normal, kicks.kick(normal, action, float(x)).normal)
                          for x in u])
        running = np.maximum.accumulate(width)
        kept_u, kept_width = [u[0]], [width[0]]
        for i in range(1, samples):
            if width[i] <= running[i - 1]:
                continue
            if width[i - 1] < running[i - 1]:
                # Climbing out of a dip: widths above the old maximum begin where the curve
                # crosses it, inside this sample interval, not at the maximum's own intensity.
                f = (running[i - 1] - width[i - 1]) / (width[i] - width[i - 1])
                kept_u.append(u[i - 1] + f * (u[i] - u[i - 1]))
                kept_width.append(running[i - 1])
            kept_u.append(u[i])
            kept_width.append(width[i])
        return cls(np.array(kept_u), np.array(kept_width))

    @property
    def full_width_rad(self) -> float:
        return float(self.widths_rad[-1])

    def design_intensity(self, intensity: float) -> float:
        """The design intensity of calibrated ``intensity`` in [0, 1]."""
        target = float(np.clip(intensity, 0.0, 1.0)) * self.full_width_rad
        w, u = self.widths_rad, self.design_intensities
        j = int(np.searchsorted(w, target, side='left'))  # the first width reaching it
        if j == 0 or w[j] == target:
            return float(u[j])
        f = (target - w[j - 1]) / (w[j] - w[j - 1])
        return float(u[j - 1] + f * (u[j] - u[j - 1]))


@dataclasses.dataclass(frozen=True)
class IntensityCalibration:
    """Calibrated intensity -> design intensity, per action of one kick model."""

    curves: tuple[ActionCurve, ...]

    @classmethod
    def of(cls, kicks: KickPlant,
           normal: NDArray[np.float64] = LEVEL_NORMAL) -> IntensityCalibration:
        """The calibration of every action of ``kicks`` from its kicks at ``normal``."""
        return cls(tuple(ActionCurve.measure(kicks, a, normal)
                         for a in range(len(kicks.directions_rad))))

    def design_intensity(self, action: int, intensity: float) -> float:
        return self.curves[action].design_intensity(intensity)

    def applied_to(self, kicks: K) -> CalibratedKicks[K]:
        """``kicks`` (the nominal model or another plant of the same actions) driven in
        calibrated intensities."""
        if len(kicks.directions_rad) != len(self.curves):
            raise ValueError(f'the calibration has {len(self.curves)} actions, the kicks '
                             f'{len(kicks.directions_rad)}')
        return CalibratedKicks(kicks, self)


def calibrated(kicks: K) -> CalibratedKicks[K]:
    """``kicks`` in calibrated intensities, from its own level-state curves: the controllers'
    view of the nominal kick model."""
    return IntensityCalibration.of(kicks).applied_to(kicks)


class CalibratedKicks(Generic[K]):
    """A kick model (a table, a plant, a twin) taking calibrated intensities.

    ``kick`` and, where the wrapped model makes programmes, ``programme`` translate the
    intensity and pass everything else through.
    """

    def __init__(self, kicks: K, calibration: IntensityCalibration) -> None:
        self.kicks = kicks
        self.calibration = calibration
        self.directions_rad = tuple(kicks.directions_rad)

    def kick(self, normal: NDArray[np.float64], action: int, intensity: float) -> KickResult:
        return self.kicks.kick(normal, action,
                               self.calibration.design_intensity(action, intensity))

    def programme(self: CalibratedKicks[P], action: int, intensity: float,
                  normal: NDArray[np.float64] = LEVEL_NORMAL) -> PulseProgramme:
        """The wrapped model's programme (:class:`~sphere_sim.model.programme.Programme`) at
        the design intensity of calibrated ``intensity``."""
        return self.kicks.programme(action, self.calibration.design_intensity(action, intensity),
                                    normal)
