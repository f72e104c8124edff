"""Plants the simulator node runs: the continuous model or the discrete kick model.

A plant holds simulated time and takes the two commands the device takes, voltages held on the
beams and a timed pulse programme, then advances to a later time and reports a
:class:`PlantSnapshot`. The node neither knows nor cares which plant it drives; a plant that
cannot carry out a command raises :class:`PlantError` and stays as it was.
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING, Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from msg_defs.device import BEAM_COUNT, KICK_WINDOW_S
from sphere_sim.integrate.solve import simulate
from sphere_sim.integrate.tolerances import LIVE_METHOD, LIVE_RTOL
from sphere_sim.kicks.discrete import NOISE_STUDY_STD_RAD, KickResult
from sphere_sim.model.assembly import Model
from sphere_sim.model.initial_state import initial_state
from sphere_sim.model.programme import PulseProgramme, VoltageSchedule
from sphere_sim.model.rotations import matrix_to_quat, quat_to_matrix

if TYPE_CHECKING:
    from sphere_sim.kicks.lookup_table import ProgrammedKickPlant

# What the live integration (LIVE_RTOL by LIVE_METHOD) is held to on a typical kick, one off the
# mirror lines and the pull-in's steps: a tenth of the sensor noise of the noise study (0.01
# widths of the paper's 0.54 deg kick, per axis), the 95th percentile of the live budget
# (docs/numerics.md, "The ladder of models").
LIVE_ERROR_BOUND_RAD = 0.1 * NOISE_STUDY_STD_RAD
# A decoded programme matches a kick of the design if its edges agree to this (a message
# carries times in whole nanoseconds) and its voltages to this. A sender's voltage offset
# (§4.1) follows the normal it measured, the plant's the normal it holds: where the shipped
# offsets are steepest (99.5 V per unit of x_sn between neighbouring nodes) the tolerance admits
# senders 2.5 mrad apart, and more elsewhere. Between nodes on the offsets' two branches the
# offset jumps by a few volts (OffsetLookup.offset_v): a sender and a plant on either side of
# that line disagree. The 41 cells with such a line lie 0.14 to 0.60 from the cone's centre.
DECODE_TIME_TOL_S = 1e-8
DECODE_VOLTAGE_TOL_V = 0.25
# Times built from sums of periods differ from products in the last bits; events this close
# count as simultaneous.
TIME_TOL_S = 1e-9


class PlantError(ValueError):
    """A command the plant cannot carry out (it is left unchanged)."""


@dataclasses.dataclass(frozen=True)
class PlantSnapshot:
    """What a plant reports at one instant.

    Attributes
    ----------
    time_s : float
    normal : ndarray, shape (3,)
        Unit surface normal in ``world``.
    voltages_v : ndarray, shape (4,)
        Voltages applied to beams 1..4 (V).
    sphere : tuple or None
        (position_m (3,), quaternion_wxyz (4,), velocity_m_per_s (3,), omega_body_rad_per_s
        (3,)) where the plant has a rigid-body sphere.
    beams : tuple or None
        (z_m (4,), phi_rad (4,), zdot_m_per_s (4,), phidot_rad_per_s (4,)) where it has beams.
    """

    time_s: float
    normal: NDArray[np.float64]
    voltages_v: NDArray[np.float64]
    sphere: tuple[NDArray[np.float64], ...] | None = None
    beams: tuple[NDArray[np.float64], ...] | None = None


class TwinPlant(Protocol):
    """What the simulator node drives."""

    time_s: float
    busy_until_s: float  # when the last command's effect is over (programme end + settling)

    def hold(self, voltages_v: ArrayLike) -> None:
        """Hold ``voltages_v`` (V, shape (4,)) on the beams from now on."""

    def run_programme(self, programme: PulseProgramme) -> None:
        """Start ``programme`` (a PulseProgramme, times from now)."""

    def advance(self, t_end_s: float) -> None:
        """Advance simulated time to ``t_end_s`` (s)."""

    def snapshot(self) -> PlantSnapshot:
        """The :class:`PlantSnapshot` now."""

    def model_state(self) -> NDArray[np.float64] | None:
        """The continuous model's state now (a copy), or None where the plant has none."""


class ContinuousPlant:
    """The physics model of §3, integrated between commands and sample times.

    Parameters
    ----------
    model : sphere_sim.model.assembly.Model
        With a sphere (its surface normal is the plant's output).
    x0 : ndarray, shape (n_states,), optional
        Initial state; the scene's initial state by default.
    rtol : float
    kick_period_s : float
        Time after a programme's start until its effect counts as over (its settle time; at
        least the programme itself).
    method : str
        The integrator (:data:`sphere_sim.integrate.solve.METHODS`).
    """

    def __init__(self, model: Model, x0: ArrayLike | None = None, rtol: float = LIVE_RTOL,
                 kick_period_s: float = KICK_WINDOW_S, method: str = LIVE_METHOD) -> None:
        if not model.has_sphere:
            raise PlantError('the continuous plant needs a scene with the sphere')
        self.model = model
        self.x = np.array(initial_state(model) if x0 is None else x0, dtype=float)
        self.rtol = rtol
        self.method = method
        self.kick_period_s = kick_period_s
        self.time_s = 0.0
        self.busy_until_s = 0.0
        self.schedule = VoltageSchedule()
        self.stats_nfev = 0

    def hold(self, voltages_v: ArrayLike) -> None:
        self.schedule.replace_from(self.time_s, [0.0], [voltages_v])

    def run_programme(self, programme: PulseProgramme) -> None:
        times, volts = programme.segments()
        self.schedule.replace_from(self.time_s, times, volts)
        self.busy_until_s = self.time_s + max(programme.duration_s, self.kick_period_s)

    def advance(self, t_end_s: float) -> None:
        if t_end_s > self.time_s:
            # The held segments go to the solver as they are; it stops at each edge. One
            # sample per segment: only the end state is kept.
            traj = simulate(self.model, self.x, t_end_s, self.schedule, rtol=self.rtol,
                            sample_period_s=t_end_s - self.time_s, t_start_s=self.time_s,
                            method=self.method)
            self.x = traj.final_state.copy()
            self.stats_nfev += traj.stats.nfev
        self.time_s = max(self.time_s, t_end_s)
        self.schedule.forget_before(self.time_s)

    def model_state(self) -> NDArray[np.float64]:
        return self.x.copy()

    def snapshot(self) -> PlantSnapshot:
        m, x = self.model, self.x
        o = m.sphere_offset
        sphere = (x[o:o + 3].copy(), x[o + 3:o + 7].copy(), x[o + 7:o + 10].copy(),
                  x[o + 10:o + 13].copy())
        beams = tuple(np.array(c, dtype=float) for c in m.beam_coordinates(x))
        return PlantSnapshot(self.time_s, m.surface_normal(x), self.schedule.voltages_at(
            self.time_s), sphere, beams)


@dataclasses.dataclass(frozen=True)
class RestPose:
    """A resting sphere and its beams as the physics puts them: what the discrete plant
    reports beside its normal, so that /sphere/state and /beams/state show the device.

    A kick table knows only where the normal lands. The sphere then rests on the same tips
    about the same geometric centre, turned by the shortest rotation from the normal it
    started at (a table has no twist about the normal); the beams rest as they started.

    Attributes
    ----------
    centre_m : ndarray, shape (3,)
        The sphere's geometric centre (the centre of its spherical face).
    rotation : ndarray, shape (3, 3)
        The sphere's orientation at ``normal`` (its third column).
    cog_offset_m : float
        From the geometric centre to the centre of gravity, along the normal (inwards).
    beam_z_m, beam_phi_rad : ndarray, shape (4,)
    """

    centre_m: NDArray[np.float64]
    rotation: NDArray[np.float64]
    cog_offset_m: float
    beam_z_m: NDArray[np.float64]
    beam_phi_rad: NDArray[np.float64]

    @classmethod
    def of_state(cls, model: Model, x: NDArray[np.float64]) -> RestPose:
        """The pose of a resting state ``x`` of ``model`` (velocities are not kept)."""
        o = model.sphere_offset
        rotation = quat_to_matrix(np.ascontiguousarray(x[o + 3:o + 7]))
        d = model.params.sphere.cog_offset_m
        z, phi, _, _ = model.beam_coordinates(x)
        # The state holds the centre of gravity, which lies d along -normal from the centre.
        return cls(x[o:o + 3] + rotation[:, 2] * d, rotation, d, np.array(z, dtype=float),
                   np.array(phi, dtype=float))

    def turned_to(self, normal: ArrayLike) -> tuple[NDArray[np.float64], ...]:
        """(position_m of the centre of gravity, quaternion_wxyz, velocity, omega): the
        sphere at rest with its normal at ``normal``, as :attr:`PlantSnapshot.sphere`."""
        n0, n = self.rotation[:, 2], np.asarray(normal, dtype=float)
        axis, cos_angle = np.cross(n0, n), float(np.dot(n0, n))
        # Rodrigues for the shortest rotation taking n0 to n (no kick turns the normal over).
        k = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]],
                      [-axis[1], axis[0], 0.0]])
        turn = np.eye(3) + k + k @ k / (1.0 + cos_angle)
        rotation = turn @ self.rotation
        return (self.centre_m - rotation[:, 2] * self.cog_offset_m, matrix_to_quat(rotation),
                np.zeros(3), np.zeros(3))

    def beams(self) -> tuple[NDArray[np.float64], ...]:
        """(z_m, phi_rad, zdot, phidot) of the resting beams, as :attr:`PlantSnapshot.beams`."""
        return (self.beam_z_m.copy(), self.beam_phi_rad.copy(), np.zeros_like(self.beam_z_m),
                np.zeros_like(self.beam_phi_rad))


def decode_kick(kick_plant: ProgrammedKickPlant, programme: PulseProgramme,
                normal: NDArray[np.float64]) -> tuple[int, float]:
    """(action, intensity) of the kick of ``kick_plant`` that ``programme`` is from rest at
    ``normal``, or PlantError.

    ``kick_plant`` offers ``design(action)``, ``programme(action, intensity, normal)`` and
    ``directions_rad``. The intensity follows from the largest voltage (an offset never rises
    above the high pair: its search stops at ``high_v - low_v``); the action from which kick has
    the same segments at that intensity.
    """
    times, volts = programme.segments()
    for action in range(len(kick_plant.directions_rad)):
        design = kick_plant.design(action)
        span = design.high_v - design.low_v
        intensity = float(np.clip((volts.max() - design.low_v) / span, 0.0, 1.0)) if span \
            else 1.0
        c_times, c_volts = kick_plant.programme(action, intensity, normal).segments()
        if (c_times.shape == times.shape and np.allclose(c_times, times, rtol=0.0,
                                                         atol=DECODE_TIME_TOL_S)
                and np.allclose(c_volts, volts, rtol=0.0, atol=DECODE_VOLTAGE_TOL_V)):
            return action, intensity
    raise PlantError('the discrete plant executes only the kicks of its table (any action, '
                     'any intensity); this programme is none of them')


class DiscretePlant:
    """The discrete model x_{t+1} = f(x_t, a_t, u_K) behind the device's interface.

    A pulse programme is decoded into the kick (action, intensity) it is, and the resting
    normal jumps to the kick's outcome at the end of the kick window; voltages other than
    0 V held on the beams are refused, since the table knows only kicks.

    Parameters
    ----------
    kick_plant : LookupTable or CombinedKickPlant
        The kicks it knows: outcomes (``kick``) and programmes (``programme``).
    normal0 : ndarray, shape (3,), optional
    window_s : float
        Delay from the programme's start to the new resting normal.
    rest : RestPose, optional
        The physics' resting sphere and beams at ``normal0``: with it, snapshots carry the
        sphere's pose and the beams' state (the landed state), not only the normal.
    """

    def __init__(self, kick_plant: ProgrammedKickPlant, normal0: ArrayLike | None = None,
                 window_s: float = KICK_WINDOW_S, rest: RestPose | None = None) -> None:
        self.kick_plant = kick_plant
        self.rest = rest
        self.normal = np.array([0.0, 0.0, 1.0] if normal0 is None else normal0, dtype=float)
        self.window_s = window_s
        self.time_s = 0.0
        self.busy_until_s = 0.0
        self.schedule = VoltageSchedule()
        self._pending: tuple[float, NDArray[np.float64]] | None = None  # (time_s, normal)
        self.kicks = 0

    def hold(self, voltages_v: ArrayLike) -> None:
        if np.any(np.asarray(voltages_v) != 0.0):
            raise PlantError('the discrete plant models kicks only: send a pulse programme, '
                             'or 0 V on every beam')
        self.schedule.replace_from(self.time_s, [0.0], [np.zeros(BEAM_COUNT)])

    def run_programme(self, programme: PulseProgramme) -> None:
        if self._pending is not None:
            raise PlantError(f'a kick is still running until t = {self._pending[0]:.4f} s')
        action, intensity = decode_kick(self.kick_plant, programme, self.normal)
        result = self.kick_plant.kick(self.normal, action, intensity)
        times, volts = programme.segments()
        self.schedule.replace_from(self.time_s, times, volts)
        done = self.time_s + max(self.window_s, programme.duration_s)
        self._pending = (done, np.asarray(result.normal, dtype=float))
        self.busy_until_s = done
        self.kicks += 1

    def advance(self, t_end_s: float) -> None:
        if self._pending is not None and t_end_s >= self._pending[0] - TIME_TOL_S:
            self.normal = self._pending[1]
            self._pending = None
        self.time_s = max(self.time_s, t_end_s)
        self.schedule.forget_before(self.time_s)

    def model_state(self) -> None:
        return None  # a table knows only where the normal lands

    def snapshot(self) -> PlantSnapshot:
        rest = self.rest
        return PlantSnapshot(self.time_s, self.normal.copy(),
                             self.schedule.voltages_at(self.time_s),
                             None if rest is None else rest.turned_to(self.normal),
                             None if rest is None else rest.beams())


class TwinKickPlant:
    """The simulator node's continuous plant as a KickPlant: the state carries over.

    Unlike :class:`ContinuousKickPlant`, which starts every kick from rest, each call sends the
    kick's programme to the twin's :class:`~sphere_sim.twin.plants.ContinuousPlant` and lets
    simulated time run on by one kick period, whatever the sphere, the beams and the friction
    bristles were doing: the closed loop runs on the same plant as the running twin. The
    ``normal`` passed in must be the plant's own (the closed loop passes back what the last
    kick returned); resting steps do not advance the plant.

    Parameters
    ----------
    kick_model : LookupTable or CombinedKickPlant
        The kicks' programmes (``programme(action, intensity, normal)``, with the voltage
        offset for the normal) and nominal directions.
    plant : sphere_sim.twin.plants.ContinuousPlant
    period_s : float
        Simulated time per kick (s), at least the longest programme.
    """

    def __init__(self, kick_model: ProgrammedKickPlant, plant: ContinuousPlant,
                 period_s: float) -> None:
        self.kick_model = kick_model
        self.plant = plant
        self.period_s = period_s
        self.directions_rad = tuple(kick_model.directions_rad)

    def kick(self, normal: NDArray[np.float64], action: int, intensity: float) -> KickResult:
        programme = self.kick_model.programme(int(action), float(intensity), normal)
        self.plant.run_programme(programme)
        self.plant.advance(self.plant.time_s + max(self.period_s, programme.duration_s))
        return KickResult(self.plant.snapshot().normal)
