"""Kicks as motion primitives: a pulse design, its intensity scaling, and one simulated kick.

The reference design is the paper's hind-left kick (§4.1): ``low_v`` on beams 1-2 and
``high_v`` on beams 3-4, rectangular, with free widths and a delay between the two rising edges.
The intensity u_K in [0, 1] scales the high pair from ``low_v`` (no kick: the same voltage on
all beams stays below pull-in) to ``high_v`` (§4.2, Fig. 10). The other kick directions are
images of a design under the device's symmetry (``sphere_sim.model.symmetry``).
"""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from msg_defs.device import KICK_WINDOW_S, VOLTAGE_LIMIT_V
from sphere_sim.integrate.relaxation import compiled_relaxation
from sphere_sim.integrate.solve import Trajectory, simulate
from sphere_sim.integrate.tolerances import DEFAULT_RTOL
from sphere_sim.kicks.discrete import KickResult
from sphere_sim.model.assembly import Model
from sphere_sim.model.initial_state import rest_state
from sphere_sim.model.programme import Pulse, PulseProgramme
from sphere_sim.model.rotations import angle_between

SETTLE_BAND_RAD = math.radians(0.005)  # "settled": within 0.005 deg of the final normal
# The rest states of the kick workloads (table nodes, the tables' direct checks, optimisations,
# the fits' kicks and thresholds): the reference's method and tolerance, compiled, in under a
# sixth of its time (docs/numerics.md, "The rest state's relaxation"); test_throughput bounds
# how far its rests and the kicks from them lie from the reference's.
KICK_RELAXATION = compiled_relaxation
KICK_SAMPLE_PERIOD_S = 2e-4


class DesignError(ValueError):
    """A kick design file that cannot be read as one."""


@dataclasses.dataclass(frozen=True)
class KickDesign:
    """Pulse parameters of one kick in its reference direction.

    Attributes
    ----------
    direction_rad : float
        Nominal polar angle of the normal's displacement (the hind-left kick: -45 deg).
    low_beams, high_beams : tuple of int
        The paper's hind-left kick (§4.1): ``low_v`` on beams 1-2 and ``high_v`` on beams 3-4.
        Under the paper's friction the sphere, lifted by the high pair, drifts to the hind left
        and the oblique impact on beams 1-2 turns it towards the front right (Fig. 5).
    low_v, high_v : float
        Amplitudes (V) at full intensity.
    width_low_s, width_high_s : float
    delay_s : float
        Rising edge of the high pair minus that of the low pair (either sign).
    """

    direction_rad: float = math.radians(-45.0)
    low_beams: tuple[int, ...] = (1, 2)
    high_beams: tuple[int, ...] = (3, 4)
    low_v: float = 35.0
    high_v: float = VOLTAGE_LIMIT_V
    width_low_s: float = 4e-3
    width_high_s: float = 4e-3
    delay_s: float = -2e-3
    voltage_limit_v: float = VOLTAGE_LIMIT_V

    def programme(self, intensity: float = 1.0, offset_v: float = 0.0,
                  offset_beam: int | None = None) -> PulseProgramme:
        """The pulse programme at intensity u_K with an optional offset on one beam.

        Raises
        ------
        ValueError
            For an intensity outside [0, 1]; ProgrammeError for voltages above the limit.
        """
        if not 0.0 <= intensity <= 1.0 or not math.isfinite(intensity):
            raise ValueError(f'intensity must lie in [0, 1], got {intensity}')
        start_low = max(0.0, -self.delay_s)
        start_high = max(0.0, self.delay_s)
        high = self.low_v + intensity * (self.high_v - self.low_v)
        pulses = []
        for beam in self.low_beams:
            amp = self.low_v + (offset_v if beam == offset_beam else 0.0)
            pulses.append(Pulse(beam, amp, start_low, self.width_low_s))
        for beam in self.high_beams:
            amp = high + (offset_v if beam == offset_beam else 0.0)
            pulses.append(Pulse(beam, amp, start_high, self.width_high_s))
        return PulseProgramme(tuple(p for p in pulses if p.amplitude_v != 0.0),
                              self.voltage_limit_v)

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def load(cls, path: str | Path) -> KickDesign:
        """The design saved by ``sphere-twin optimize-kick`` (its JSON's ``design``).

        Raises
        ------
        DesignError
            For a file that is not such a JSON (OSError for one that cannot be read).
        """
        try:
            data = dict(json.loads(Path(path).read_text())['design'])
            data.pop('direction_deg', None)
            data['low_beams'] = tuple(data['low_beams'])
            data['high_beams'] = tuple(data['high_beams'])
            return cls(**data)
        except (json.JSONDecodeError, KeyError, TypeError, ValueError) as exc:
            raise DesignError(f'{path} is not a kick design saved by `sphere-twin '
                              f'optimize-kick`: {type(exc).__name__}: {exc}') from exc


def cardan_of_normal(normal: NDArray[np.float64]) -> tuple[float, float, float]:
    """(alpha, beta, 0) in degrees whose surface normal (eq. 53) is ``normal``."""
    nx, ny, nz = normal
    beta = math.asin(max(-1.0, min(1.0, nx)))
    alpha = math.atan2(-ny, nz)
    return (math.degrees(alpha), math.degrees(beta), 0.0)


def simulate_kick(model: Model, normal: NDArray[np.float64], programme: PulseProgramme,
                  window_s: float = KICK_WINDOW_S, rtol: float = DEFAULT_RTOL,
                  x_rest: NDArray[np.float64] | None = None,
                  method: str = 'fast') -> tuple[KickResult, Trajectory]:
    """One kick from rest at ``normal``; returns the KickResult and the trajectory.

    Parameters
    ----------
    model : Model
        With sphere and all four beams.
    normal : ndarray, shape (3,)
        Resting surface normal before the kick.
    programme : PulseProgramme
    window_s : float
        The outcome is the normal at the end of this window.
    x_rest : ndarray, optional
        A precomputed rest state for ``normal``.
    """
    if x_rest is None:
        x_rest = rest_state(model, cardan_of_normal(normal))
    traj = simulate(model, x_rest, window_s, programme, rtol=rtol,
                    sample_period_s=KICK_SAMPLE_PERIOD_S, method=method)
    normals = traj.surface_normal()
    final = normals[:, -1]
    deviation = deviations_rad(normals, final)
    outside = np.flatnonzero(deviation > SETTLE_BAND_RAD)
    settle = float(traj.t[outside[-1] + 1] if outside.size else traj.t[0])
    return KickResult(final, float(np.max(deviation)), settle), traj


def deviations_rad(normals: NDArray[np.float64],
                   final: NDArray[np.float64]) -> NDArray[np.float64]:
    """Angle (rad) of each column of ``normals`` from ``final``: :func:`angle_between`'s
    numbers to the bit, with the cross products taken at once (one call per sample cost a
    kick ~13 ms, 5 % of it)."""
    cross = np.cross(normals.T, final)
    return np.array([math.atan2(np.linalg.norm(c), float(n @ final))
                     for c, n in zip(cross, normals.T, strict=True)])


def final_normal(model: Model, normal: NDArray[np.float64], programme: PulseProgramme,
                 window_s: float = KICK_WINDOW_S, rtol: float = DEFAULT_RTOL,
                 x_rest: NDArray[np.float64] | None = None, method: str = 'fast',
                 sample_period_s: float = KICK_SAMPLE_PERIOD_S) -> NDArray[np.float64]:
    """The resting normal after a kick: :func:`simulate_kick`'s ``normal``, the same number,
    without the transient's peak and settling time (which take a Python loop over samples).
    ``sample_period_s`` at least ``window_s`` keeps only the end state."""
    if x_rest is None:
        x_rest = rest_state(model, cardan_of_normal(normal))
    traj = simulate(model, x_rest, window_s, programme, rtol=rtol,
                    sample_period_s=sample_period_s, method=method)
    return model.surface_normal(traj.x[:, -1])


def displacement(normal_before: NDArray[np.float64],
                 normal_after: NDArray[np.float64]) -> tuple[float, float]:
    """(rotation angle in rad, polar direction in rad) of the normal's x-y displacement."""
    d = np.asarray(normal_after[:2]) - np.asarray(normal_before[:2])
    return angle_between(normal_before, normal_after), math.atan2(d[1], d[0])
