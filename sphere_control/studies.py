"""The closed-loop studies of §5, and two beyond it (eight directions, a Kalman filter).

Everything runs on a discrete KickPlant, normally the shipped lookup table: the sphere rests
stably between kicks, as the paper's discrete model assumes (the contacts' friction holds it,
docs/parameters.md).

Intensity. The controllers speak in calibrated intensities: u_K is defined through the nominal
plant's level-state width curve (:mod:`sphere_control.intensity_calibration`), made once from
the plant under test, and every plant the studies drive takes it.

Set-ups, side by side (:class:`SetUp`, :data:`SET_UPS`). The paper's full kick turns the normal
by 0.54 deg; a plant may kick more or less (the calibrated table: 0.508 deg, nothing fitted to
it). The paper's set-up runs §5 as given: f1 = 0.02 Hz, Phi_min of 0.05 and 0.25 deg (the basic
controller's best of the two in Fig. 15), the kick period the full kick's settle time; sigma_a
learns from kicks longer than the nominal model's stray kicks (a calibration of the table,
:func:`~sphere_control.controllers.direction_learning_floor_rad`), and a second set-up learning
it from every kick, as the paper does, stands beside it (:data:`PAPER_SETUP` says why). Ours
scales f1 and Phi_min by the kick-size ratio (what decides whether the basic controller
oscillates is Phi_min against the kick width, and the reference then advances the same fraction
of a kick per kick) and searches the basic band over a few kick widths. Distances in the
setpoint scenario are the paper's in all (the reference is 1.28 deg away). All aim with
reference preview unless told not to.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import time
from collections.abc import Iterable, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from msg_defs.device import KICK_WINDOW_S
from sphere_control import reference as ref
from sphere_control.closed_loop import (
    NO_ACTION,
    LoopHistory,
    LoopSettings,
    Outcome,
    run_closed_loop,
)
from sphere_control.command import Controller
from sphere_control.controllers import (
    ControllerKind,
    direction_learning_floor_rad,
    make_controller,
)
from sphere_control.estimator import KalmanParams, NormalKalmanFilter
from sphere_control.extended import prelearn
from sphere_control.intensity_calibration import IntensityCalibration, calibrated
from sphere_control.perturbations import Mismatch, NoisySensor, PerturbedPlant
from sphere_control.reachable import (
    best_single_kick,
    kick_vectors,
    reach_per_kick,
    reference_steps,
    speed_ratios,
)
from sphere_control.reference import CircleTrajectory, Setpoint
from sphere_sim.kicks.discrete import (
    CONE_HALF_ANGLE_RAD,
    LEVEL_NORMAL,
    PAPER_FULL_KICK_RAD,
    KickPlant,
    KickResult,
    settled_kick_period_s,
)
from sphere_sim.model.rotations import angle_between

if TYPE_CHECKING:
    from sphere_sim.kicks.lookup_table import LookupTable

# The paper's numbers (§4.1, §5).
PAPER_SETPOINT_NORMAL = (0.01, 0.02, 0.9997)
PAPER_PHI_MIN_RAD = (math.radians(0.05), math.radians(0.25))
PAPER_SETPOINT_MISMATCH_RAD = math.radians(12.0)
PAPER_TRAJECTORY_MISMATCH_RAD = math.radians(33.0)
PAPER_TRAJECTORY = CircleTrajectory(amplitude=0.44, frequency_hz=0.02)

# An axis-parallel setpoint (as far as the paper's one, along +x), where eight directions should
# help most.
AXIS_SETPOINT_NORMAL = (math.hypot(0.01, 0.02), 0.0, 0.9997)
# A run counts as oscillating if it never settled and its last OSCILLATION_KICKS errors all stay
# within OSCILLATION_BAND_WIDTHS full kick widths of the reference: it circles the reference.
OSCILLATION_KICKS = 10
OSCILLATION_BAND_WIDTHS = 2.0
# The tracking phase of a trajectory run starts when both compared runs are within this many
# full kick widths of the reference; before that both kick at full width towards the start of
# the trajectory (26 deg away), which says nothing about tracking.
CATCH_UP_WIDTHS = 2.0
# Under measurement noise of std s per component, a displacement from two measured normals has
# noise std sqrt(2) s per component; shorter than this many of those, its direction is mostly
# noise, and eq. (61) at alpha_sigma = 0.9 would adopt it. Used as the extended controller's
# direction-learning threshold in the noise study (with and without the filter alike).
NOISE_LEARNING_SIGMAS = 3.0


@dataclasses.dataclass(frozen=True)
class SetUp:
    """Whose settings a study runs with (module docstring).

    Attributes
    ----------
    name : str
    scaled : bool
        f1 and Phi_min times the kick scale, and the basic band searched over
        ``EvaluationConfig.basic_phi_min_widths``; otherwise the paper's f1 and Phi_min, and
        the basic controller's best of the paper's two bands.
    sigma_from_every_kick : bool
        sigma_a learns from every kick that moved the sphere (the paper), or only from kicks
        longer than the nominal model's stray kicks (:func:`direction_learning_floor_rad`).
    """

    name: str
    scaled: bool
    sigma_from_every_kick: bool

    def phi_min_rad(self, paper_phi_min_rad: float, put: PlantUnderTest) -> float:
        """A Phi_min of the paper (rad) in this set-up: as given, or times the kick scale."""
        return paper_phi_min_rad * (put.kick_scale if self.scaled else 1.0)

    def trajectory(self, put: PlantUnderTest) -> CircleTrajectory:
        """Eq. (64): the paper's f1, or f1 times the kick scale."""
        if not self.scaled:
            return PAPER_TRAJECTORY
        return CircleTrajectory(PAPER_TRAJECTORY.amplitude,
                                PAPER_TRAJECTORY.frequency_hz * put.kick_scale)

    def basic_bands_rad(self, config: EvaluationConfig,
                        put: PlantUnderTest) -> tuple[float, ...]:
        """The Phi_min the basic controller tries in Fig. 15, the best one kept (rad)."""
        if not self.scaled:
            return PAPER_PHI_MIN_RAD
        return tuple(f * put.full_width_rad for f in config.basic_phi_min_widths)

    def direction_learning_min_rad(self, put: PlantUnderTest) -> float:
        """The shortest kick that teaches sigma_a (rad)."""
        return 0.0 if self.sigma_from_every_kick else put.direction_floor_rad


# The paper's §5 as given, but for sigma_a, which learns only from kicks longer than the table's
# stray kicks: below the pull-in a programme slips a tilted sphere in a direction of its own (by
# 0.002 deg at u_K = 0, up to 0.1 deg just below the pull-in: the ratchet, docs/parameters.md),
# and eq. (61) at alpha_sigma = 0.9 would adopt that direction. The set-up that learns from
# every kick stands beside it (docs/control.md).
PAPER_SETUP = SetUp('paper', scaled=False, sigma_from_every_kick=False)
EVERY_KICK_SETUP = SetUp('paper, sigma from every kick', scaled=False,
                         sigma_from_every_kick=True)
OUR_SETUP = SetUp('ours', scaled=True, sigma_from_every_kick=False)
SET_UPS = (PAPER_SETUP, EVERY_KICK_SETUP, OUR_SETUP)


@dataclasses.dataclass(frozen=True)
class EvaluationConfig:
    """Sizes of the studies.

    Attributes
    ----------
    kick_period_s : float or None
        Time per decision in the trajectory runs (s). None: the plant's own, its full kick's
        settle time rounded up (:attr:`PlantUnderTest.kick_period_s`).
    kick_period_sweep_s : tuple of float
        Further kick periods at which the trajectory ratio is reported (s).
    trajectory_periods : float
        Length of the trajectory runs in periods 1/f1 of eq. (64) (one period: two laps).
    basic_phi_min_widths : tuple of float
        Phi_min of the basic controller in our set-up's trajectory runs, in full kick widths;
        the best (lowest tracking error) is compared, as in Fig. 15 ("the best result of the
        basic controller").
    extended_phi_min_rad : float
        Phi_min of the extended controller in the trajectory runs, as the paper gives it
        (scaled by the kick scale in our set-up).
    setpoint_max_steps : int
    prelearn_kicks : int
    noise_std_widths : tuple of float
        Measurement noise stds per x-y component, in full kick widths (Kalman study).
    continuous_kicks : int
        Kicks of the setpoint scenario on the continuous model (0: skip).
    twin_trajectory_periods : float
        Length of the Fig. 15 run on the twin's continuous plant, in periods 1/f1 (0: skip
        the twin study; see :func:`twin_study`).
    seed : int
    """

    # The paper does not give the kick period. A kick must have settled before the next is
    # decided, so the default is the plant's settle time, rounded up.
    kick_period_s: float | None = None
    kick_period_sweep_s: tuple[float, ...] = (0.03, 0.06, 0.12)
    trajectory_periods: float = 1.0
    basic_phi_min_widths: tuple[float, ...] = (0.25, 0.5, 0.75, 1.0)
    extended_phi_min_rad: float = PAPER_PHI_MIN_RAD[0]
    setpoint_max_steps: int = 400
    prelearn_kicks: int = 40
    noise_std_widths: tuple[float, ...] = (0.1, 0.25)
    continuous_kicks: int = 6
    twin_trajectory_periods: float = 0.25
    seed: int = 0

    @classmethod
    def quick(cls) -> EvaluationConfig:
        """Shorter runs for a smoke check (one lap of the trajectory, two continuous kicks)."""
        return cls(kick_period_sweep_s=(0.03,), trajectory_periods=0.5,
                   basic_phi_min_widths=(0.25, 0.5, 1.0), continuous_kicks=2,
                   twin_trajectory_periods=0.0)

    def for_plant(self, put: PlantUnderTest) -> EvaluationConfig:
        """This configuration with the kick period resolved for ``put``."""
        if self.kick_period_s is not None:
            return self
        return dataclasses.replace(self, kick_period_s=put.kick_period_s)


@dataclasses.dataclass(frozen=True)
class PlantUnderTest:
    """A KickPlant in calibrated intensities, with its full kick width and settle time measured
    from the level state.

    ``calibration`` is the plant's own (:class:`IntensityCalibration`); the studies lay it on
    every other plant they drive in its place (the continuous model, the twin).
    """

    label: str
    plant: KickPlant
    full_width_rad: float
    settle_time_s: float = 0.0
    calibration: IntensityCalibration | None = None
    direction_floor_rad: float = 0.0

    @classmethod
    def measure(cls, label: str, plant: KickPlant) -> PlantUnderTest:
        """``plant`` calibrated from its own level-state width curve, and measured (its full
        kick, and its longest stray kick: :func:`direction_learning_floor_rad`)."""
        kicks = calibrated(plant)
        full = kicks.kick(LEVEL_NORMAL, 0, 1.0)
        return cls(label, kicks, angle_between(LEVEL_NORMAL, full.normal),
                   float(full.settle_time_s), kicks.calibration,
                   direction_learning_floor_rad(plant))

    def calibrated(self, plant: KickPlant) -> KickPlant:
        """Another plant of the same actions, driven in this plant's calibrated intensities."""
        return plant if self.calibration is None else self.calibration.applied_to(plant)

    @property
    def kick_period_s(self) -> float:
        """The shortest decision period at which a full kick has settled before the next
        decision: its settle time rounded up (:func:`settled_kick_period_s`); the kick window for a
        plant that reports no settle time (the analytic one)."""
        return settled_kick_period_s(self.settle_time_s)

    @property
    def kick_scale(self) -> float:
        """Our full kick over the paper's 0.54 deg."""
        return self.full_width_rad / PAPER_FULL_KICK_RAD


def study_controller(kind: ControllerKind, phi_min: float, put: PlantUnderTest, plant: KickPlant,
                     config: EvaluationConfig, directions_rad: Sequence[float] | None = None,
                     direction_learning_min_rad: float = 0.0,
                     ) -> Controller:
    """A fresh controller of ``kind`` whose model is the nominal plant ``put``.

    The pre-learned one has first learned on ``plant`` (the device it will run on).
    """
    controller = make_controller(kind, phi_min, put.full_width_rad,
                                 directions_rad or plant.directions_rad,
                                 direction_learning_min_rad)
    if kind is ControllerKind.PRELEARNED:
        prelearn(controller, plant, LEVEL_NORMAL, config.prelearn_kicks, config.seed)
    return controller


def oscillates(history: LoopHistory, full_width_rad: float) -> bool:
    """Never settled, and the last kicks all circle the reference within a few kick widths."""
    if history.outcome is Outcome.SETTLED or history.kicks < OSCILLATION_KICKS:
        return False
    recent = history.errors_rad[-OSCILLATION_KICKS:]
    return bool(np.all(recent <= OSCILLATION_BAND_WIDTHS * full_width_rad))


def reversed_kicks(history: LoopHistory, n_actions: int) -> int:
    """Kicks that undo the kick before them (the opposite action, half the actions on): the
    basic controller's oscillation about a reference, counted even when it ends."""
    kicks = history.actions[history.actions != NO_ACTION]
    return int(np.count_nonzero(kicks[1:] == (kicks[:-1] + n_actions // 2) % n_actions))


def setpoint_summary(history: LoopHistory, full_width_rad: float,
                     n_actions: int = 4) -> dict[str, Any]:
    """JSON-able figures of one setpoint run (angles in degrees)."""
    return {
        'outcome': history.outcome.value,
        'kicks': history.kicks,
        'kicks_to_settle': history.kicks_to_settle,
        'final_error_deg': math.degrees(history.final_error_rad),
        'oscillates': oscillates(history, full_width_rad),
        'reversed_kicks': reversed_kicks(history, n_actions),
    }


def setpoint_study(put: PlantUnderTest, plant: KickPlant, reference_normal: ArrayLike,
                   phi_min: float, config: EvaluationConfig,
                   kinds: Iterable[ControllerKind] = tuple(ControllerKind),
                   directions_rad: Sequence[float] | None = None,
                   setup: SetUp = PAPER_SETUP) -> dict[ControllerKind, LoopHistory]:
    """One setpoint scenario for several controllers; dict kind -> LoopHistory."""
    settings = LoopSettings(max_steps=config.setpoint_max_steps, kick_period_s=KICK_WINDOW_S)
    reference = Setpoint.from_normal(reference_normal)
    return {kind: run_closed_loop(study_controller(kind, phi_min, put, plant, config,
                                                  directions_rad,
                                                  setup.direction_learning_min_rad(put)),
                                  plant, LEVEL_NORMAL, reference, settings)
            for kind in kinds}


def speed_study(put: PlantUnderTest, plant: KickPlant, config: EvaluationConfig,
                setup: SetUp = PAPER_SETUP) -> dict[str, Any]:
    """Where on eq. (64) the reference outruns the plant (:mod:`sphere_control.reachable`).

    Over one period of the set-up's trajectory, one kick period at a time: the reference's step
    against the furthest the plant can move along it per kick, by the kicks the true ``plant``
    makes at the reference's normal, and by the controllers' nominal model (``put``'s width
    along the nominal directions). Angles in degrees, tilts from the vertical.
    """
    period = config.for_plant(put).kick_period_s
    assert period is not None  # for_plant resolves it
    trajectory = setup.trajectory(put)
    times = np.arange(0.0, 1.0 / trajectory.frequency_hz, period)
    cone = CONE_HALF_ANGLE_RAD
    normals = [ref.sample(trajectory, t, cone).normal for t in times]
    steps = reference_steps(trajectory, times, period, cone)
    actions = range(len(plant.directions_rad))

    def true_kicks(i: int) -> NDArray[np.float64]:
        n = normals[i]
        return np.array([plant.kick(n, a, 1.0).normal[:2] - n[:2] for a in actions])

    nominal = kick_vectors(plant.directions_rad, put.full_width_rad)
    tilt_deg = np.degrees([angle_between(LEVEL_NORMAL, n) for n in normals])
    out: dict[str, Any] = {'kick_period_s': period,
           'needed_per_kick_deg_max': math.degrees(float(np.max(np.hypot(*steps.T))))}
    for name, kicks_at in (('plant', true_kicks), ('model', lambda i: nominal)):
        for how, reach in (('', reach_per_kick), ('single_', best_single_kick)):
            ratios = speed_ratios(steps, kicks_at, reach)
            fast = ratios > 1.0
            out.setdefault(name, {}).update({
                f'{how}fraction_outrun': float(np.mean(fast)),
                f'{how}max_ratio': float(np.max(ratios)),
                f'{how}tilt_deg_outrun': ([float(tilt_deg[fast].min()),
                                           float(tilt_deg[fast].max())] if fast.any() else None)})
    return out


def catch_up_step(histories: Iterable[LoopHistory], full_width_rad: float) -> int:
    """First step from which every run has once been within CATCH_UP_WIDTHS kick widths."""
    limit = (CATCH_UP_WIDTHS * full_width_rad) ** 2
    steps = []
    for h in histories:
        inside = np.flatnonzero(h.squared_xy_errors <= limit)
        if inside.size:  # a run that never gets close does not hold the others back
            steps.append(int(inside[0]))
    return max(steps, default=0)


@dataclasses.dataclass(frozen=True)
class TrackingResult:
    """Trajectory runs of the best basic and the extended controller.

    Attributes
    ----------
    basic, extended : LoopHistory
    basic_phi_min_rad : float
        Phi_min of the best basic run.
    catch_up_step : int
    mse_basic, mse_extended : float
        Mean squared x-y error over the tracking phase.
    mse_basic_all, mse_extended_all : float
        The same over the whole run, the approach from the level state included.
    mse_basic_aimed, mse_extended_aimed : float
        Over the tracking phase, each outcome against the reference its kick aimed at
        (:attr:`LoopHistory.squared_xy_aim_errors`) instead of the reference at its time.
    """

    basic: LoopHistory
    extended: LoopHistory
    basic_phi_min_rad: float
    catch_up_step: int
    mse_basic: float
    mse_extended: float
    mse_basic_all: float
    mse_extended_all: float
    mse_basic_aimed: float
    mse_extended_aimed: float

    @classmethod
    def of(cls, basic: LoopHistory, extended: LoopHistory, basic_phi_min_rad: float,
           catch_up_step: int) -> TrackingResult:
        def mse(errors: NDArray[np.float64]) -> float:
            return float(np.mean(errors))

        start = catch_up_step
        return cls(basic, extended, basic_phi_min_rad, start,
                   mse(basic.squared_xy_errors[start:]), mse(extended.squared_xy_errors[start:]),
                   mse(basic.squared_xy_errors), mse(extended.squared_xy_errors),
                   # aim error k scores state k + 1: the same states as above
                   mse(basic.squared_xy_aim_errors[max(start - 1, 0):]),
                   mse(extended.squared_xy_aim_errors[max(start - 1, 0):]))

    @property
    def ratio(self) -> float:
        """MSE extended/basic, each outcome scored against the reference at its time."""
        return self.mse_extended / self.mse_basic

    @property
    def ratio_aimed(self) -> float:
        """MSE extended/basic, each outcome scored against the reference its kick aimed at."""
        return self.mse_extended_aimed / self.mse_basic_aimed

    def summary(self) -> dict[str, float]:
        return {'basic_phi_min_deg': math.degrees(self.basic_phi_min_rad),
                'catch_up_step': self.catch_up_step, 'steps': len(self.basic.actions),
                'mse_basic': self.mse_basic, 'mse_extended': self.mse_extended,
                'mse_ratio': self.ratio, 'mse_basic_whole_run': self.mse_basic_all,
                'mse_extended_whole_run': self.mse_extended_all,
                'mse_ratio_whole_run': self.mse_extended_all / self.mse_basic_all,
                'mse_basic_aimed': self.mse_basic_aimed,
                'mse_extended_aimed': self.mse_extended_aimed,
                'mse_ratio_aimed': self.ratio_aimed}


def tracking_study(put: PlantUnderTest, plant: KickPlant, config: EvaluationConfig,
                   kick_period_s: float | None = None,
                   directions_rad: Sequence[float] | None = None,
                   noise: tuple[float, bool] | None = None,
                   basic_bands_rad: Sequence[float] | None = None, preview: bool = True,
                   setup: SetUp = PAPER_SETUP) -> TrackingResult:
    """Fig. 15: the set-up's eq. (64) trajectory, the best basic against the extended.

    Parameters
    ----------
    noise : tuple (std_rad, use_kalman) or None
        Measurement noise, seeded from ``config.seed``, with or without the Kalman filter.
    basic_bands_rad : tuple of float, optional
        The basic controller's Phi_min to try (rad); by default the set-up's.
    preview : bool
        Both controllers aim where the reference will be when the kick has settled
        (:class:`LoopSettings`), not at the current sample.
    setup : SetUp
    """
    period = config.for_plant(put).kick_period_s if kick_period_s is None else kick_period_s
    assert period is not None  # for_plant resolves it
    trajectory = setup.trajectory(put)
    steps = round(config.trajectory_periods / trajectory.frequency_hz / period)
    settings = LoopSettings(max_steps=steps, kick_period_s=period, preview=preview)
    W = put.full_width_rad
    learning_min = setup.direction_learning_min_rad(put)
    if noise is not None:
        learning_min = max(learning_min, NOISE_LEARNING_SIGMAS * math.sqrt(2.0) * noise[0])

    def run(controller: Controller) -> LoopHistory:
        sensor: NoisySensor | None = None
        estimator: NormalKalmanFilter | None = None
        if noise is not None:
            std, use_kalman = noise
            sensor = NoisySensor(std, config.seed)
            if use_kalman:
                estimator = NormalKalmanFilter(KalmanParams(std, 0.1 * W), LEVEL_NORMAL)
        return run_closed_loop(controller, plant, LEVEL_NORMAL, trajectory, settings,
                               sensor, estimator)

    extended = run(study_controller(ControllerKind.EXTENDED,
                                   setup.phi_min_rad(config.extended_phi_min_rad, put), put,
                                   plant, config, directions_rad, learning_min))
    bands = setup.basic_bands_rad(config, put) if basic_bands_rad is None else basic_bands_rad
    basics = [(phi, run(study_controller(ControllerKind.BASIC, phi, put, plant, config,
                                        directions_rad)))
              for phi in bands]
    start = catch_up_step([extended] + [h for _, h in basics], W)
    phi, basic = min(basics, key=lambda p: float(np.mean(p[1].squared_xy_errors[start:])))
    return TrackingResult.of(basic, extended, phi, start)


def continuous_study(table: LookupTable, put: PlantUnderTest, config: EvaluationConfig,
                     continuous_plant: KickPlant | None = None) -> dict[str, Any] | None:
    """§5 setpoint scenario for a few kicks on the continuous model and on the table.

    The extended controller (fresh, the paper's set-up at Phi_min = 0.05 deg) runs on both
    plants, in ``put``'s calibrated intensities. The
    table's one-step prediction along the continuous run tells how well the discrete model
    stands for the continuous one; the continuous kicks also show the transient overshoot the
    discrete model hides.
    """
    if config.continuous_kicks <= 0:
        return None
    if continuous_plant is None:
        from sphere_sim.kicks.continuous_kicks import ContinuousKickPlant

        continuous_plant = ContinuousKickPlant(table.spec, table.parameters())
    recorder = _RecordingPlant(continuous_plant)
    continuous = put.calibrated(recorder)
    nominal = put.calibrated(table)
    phi = PAPER_PHI_MIN_RAD[0]
    learning_min = PAPER_SETUP.direction_learning_min_rad(put)
    settings = LoopSettings(max_steps=config.continuous_kicks, kick_period_s=KICK_WINDOW_S)
    reference = Setpoint.from_normal(PAPER_SETPOINT_NORMAL)
    started = time.perf_counter()
    cont = run_closed_loop(study_controller(ControllerKind.EXTENDED, phi, put, nominal, config,
                                            direction_learning_min_rad=learning_min),
                           continuous, LEVEL_NORMAL, reference, settings)
    wall_s = time.perf_counter() - started
    disc = run_closed_loop(study_controller(ControllerKind.EXTENDED, phi, put, nominal, config,
                                            direction_learning_min_rad=learning_min),
                           nominal, LEVEL_NORMAL, reference, settings)
    one_step: list[tuple[float, float]] = []
    for k, action in enumerate(cont.actions):
        if action == NO_ACTION:
            continue
        predicted = nominal.kick(cont.normals[k], int(action),
                                 float(cont.intensities[k])).normal
        moved = angle_between(cont.normals[k], cont.normals[k + 1])
        one_step.append((angle_between(predicted, cont.normals[k + 1]), moved))
    n = min(len(cont.normals), len(disc.normals))
    gaps = [angle_between(a, b) for a, b in zip(cont.normals[:n], disc.normals[:n], strict=True)]
    return {
        'kicks': cont.kicks,
        'wall_time_per_kick_s': wall_s / max(1, cont.kicks),
        'one_step_error_deg': [math.degrees(e) for e, _ in one_step],
        'one_step_rotation_deg': [math.degrees(m) for _, m in one_step],
        'run_gap_deg': [math.degrees(g) for g in gaps],
        'error_continuous_deg': [math.degrees(e) for e in cont.errors_rad],
        'error_table_deg': [math.degrees(e) for e in disc.errors_rad],
        'intensities_continuous': cont.intensities.tolist(),
        'intensities_table': disc.intensities.tolist(),
        'peak_deviation_deg': [math.degrees(r.peak_deviation_rad) for r in recorder.results],
        'settle_time_s': [r.settle_time_s for r in recorder.results],
    }


def twin_study(table: LookupTable, put: PlantUnderTest, config: EvaluationConfig,
               basic_phi_min_rad: float) -> dict[str, Any]:
    """The Fig. 13 setpoint and a stretch of the Fig. 15 circle on the twin's continuous plant
    (:class:`~sphere_control.kick_plants.TwinKickPlant`: the state carries from kick to kick,
    as in the simulator node) beside the same runs on the table.

    The 33 deg mismatch of Fig. 15 cannot be laid on a physical plant's kicks; it is laid on the
    controllers' belief instead: they take the kicks' directions to be 33 deg short of what
    they are, on both plants. The runs are the paper's set-up in ``put``'s calibrated
    intensities; the basic controller runs at ``basic_phi_min_rad``, the best on the table.
    """
    from sphere_sim.integrate.solve import DEFAULT_METHOD
    from sphere_sim.model.assembly import assemble
    from sphere_sim.model.initial_state import rest_state
    from sphere_sim.model.scene import load_scene
    from sphere_sim.twin.plants import ContinuousPlant, TwinKickPlant

    config = config.for_plant(put)
    period = config.kick_period_s
    assert period is not None  # for_plant resolves it
    model = assemble(load_scene('rest'), table.parameters())
    x_level = rest_state(model)
    setup = PAPER_SETUP
    learning_min = setup.direction_learning_min_rad(put)
    nominal = put.calibrated(table)

    def fresh_twin() -> KickPlant:
        # Integrated as the studies are (solve.DEFAULT_METHOD), not by the live twin's cheaper
        # method: the figures are the controllers' on the physics.
        plant = ContinuousPlant(model, x_level.copy(), method=DEFAULT_METHOD)
        return put.calibrated(TwinKickPlant(table, plant, period))

    setpoint = Setpoint.from_normal(PAPER_SETPOINT_NORMAL)
    settings = LoopSettings(max_steps=config.setpoint_max_steps, kick_period_s=period)
    out: dict[str, Any] = {'kick_period_s': period, 'setpoint': {}, 'trajectory': {}}
    for kind in (ControllerKind.BASIC, ControllerKind.EXTENDED):
        runs = {name: run_closed_loop(study_controller(kind, PAPER_PHI_MIN_RAD[0], put, nominal,
                                                       config,
                                                       direction_learning_min_rad=learning_min),
                                      plant, LEVEL_NORMAL, setpoint, settings)
                for name, plant in (('twin', fresh_twin()), ('table', nominal))}
        out['setpoint'][kind.value] = {k: setpoint_summary(h, put.full_width_rad)
                                       for k, h in runs.items()}
    trajectory = setup.trajectory(put)
    steps = round(config.twin_trajectory_periods / trajectory.frequency_hz / period)
    believed = tuple(d - PAPER_TRAJECTORY_MISMATCH_RAD for d in table.directions_rad)
    for preview, kind in itertools.product((False, True),
                                           (ControllerKind.BASIC, ControllerKind.EXTENDED)):
        phi = (basic_phi_min_rad if kind is ControllerKind.BASIC
               else setup.phi_min_rad(config.extended_phi_min_rad, put))
        settings = LoopSettings(max_steps=steps, kick_period_s=period, preview=preview)
        runs = {name: run_closed_loop(study_controller(kind, phi, put, nominal, config, believed,
                                                       learning_min),
                                      plant, LEVEL_NORMAL, trajectory, settings)
                for name, plant in (('twin', fresh_twin()), ('table', nominal))}
        start = catch_up_step(list(runs.values()), put.full_width_rad)
        key = kind.value + (' with preview' if preview else '')
        out['trajectory'][key] = {
            name: {'mse': float(np.mean(h.squared_xy_errors[start:])), 'kicks': h.kicks,
                   'final_error_deg': math.degrees(h.final_error_rad)}
            for name, h in runs.items()}
        out['trajectory'][key]['catch_up_step'] = start
    out['trajectory']['steps'] = steps
    return out


class _RecordingPlant:
    """Passes kicks through and keeps their KickResults."""

    def __init__(self, plant: KickPlant) -> None:
        self.plant = plant
        self.directions_rad = plant.directions_rad
        self.results: list[KickResult] = []

    def kick(self, normal: NDArray[np.float64], action: int, intensity: float) -> KickResult:
        result = self.plant.kick(normal, action, intensity)
        self.results.append(result)
        return result


def trajectory_plant(put: PlantUnderTest) -> PerturbedPlant:
    """The plant of Fig. 15: ``put`` with the kicks turned by the paper's 33 deg."""
    return PerturbedPlant(put.plant, Mismatch(PAPER_TRAJECTORY_MISMATCH_RAD))
