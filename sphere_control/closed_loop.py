"""Run a controller against a KickPlant, one decision per kick period, and keep the history.

Each step the (noisy, optionally filtered) normal is measured, the reference sampled, and the
controller either rests or kicks; the next measurement teaches it what the kick did. The
sequencing is the controller node's own :class:`~sphere_control.kick_cycle.KickCycle`, with
this loop as the plant that reports each kick's start and end. A run ends
when a constant reference is reached and held (SETTLED), when no kick has brought the sphere
closer for a while (STALLED), when the plant refuses a kick (PLANT_LIMIT), when a reference
outside the reachable cone is refused (UNREACHABLE), or after its step budget (NOT_SETTLED for
setpoints, COMPLETED for trajectories). The outcome never leaves a loop kicking forever.
"""

from __future__ import annotations

import dataclasses
import enum
import math
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

from msg_defs.device import KICK_WINDOW_S
from sphere_control import reference as ref
from sphere_control.geometry import error_angle_rad
from sphere_control.kick_cycle import KickCycle
from sphere_sim.kicks.discrete import CONE_HALF_ANGLE_RAD

if TYPE_CHECKING:
    from sphere_control.command import Controller
    from sphere_control.estimator import NormalKalmanFilter
    from sphere_control.perturbations import NoisySensor
    from sphere_control.reference import Reference, ReferenceSample
    from sphere_sim.kicks.discrete import KickPlant

NO_ACTION = -1  # the action recorded for a step spent resting


class Outcome(enum.Enum):
    SETTLED = 'settled'  # constant reference: resting for settle_rest_steps in a row
    NOT_SETTLED = 'not settled'  # constant reference: still kicking when the budget ran out
    STALLED = 'stalled'  # no kick brought the normal closer for stall_kicks kicks
    UNREACHABLE = 'unreachable'  # the reference lies outside the cone and the policy refuses it
    PLANT_LIMIT = 'plant limit'  # the plant cannot kick from the state reached
    COMPLETED = 'completed'  # time-varying reference followed for the whole budget


class ConePolicy(enum.Enum):
    """What to do with a reference outside the reachable cone."""

    CLAMP = 'clamp'  # steer to the nearest normal on the cone's edge, flag the history
    REFUSE = 'refuse'  # stop at once with Outcome.UNREACHABLE


@dataclasses.dataclass(frozen=True)
class LoopSettings:
    """Budget and stopping rules of a run.

    Attributes
    ----------
    max_steps : int
        Decisions (kick or rest) at most.
    kick_period_s : float
        Time between decisions (s): the kick window, since a kick must settle before the next.
    settle_rest_steps : int
        A constant reference counts as reached after this many rests in a row.
    stall_kicks : int
        Stop as STALLED if this many consecutive kicks did not beat the best error so far by
        ``stall_progress_rad`` (constant references only).
    stall_progress_rad : float
    cone_policy : ConePolicy
    cone_half_angle_rad : float
    preview : bool
        Reference preview: decide towards where the reference will be one kick period later,
        when the kick has settled, by its motion at the decision (a jump ahead is not
        foreseen), instead of towards the current sample (the default; the
        paper aims at the current sample, docs/control.md). The errors are measured against
        the current sample either way; :attr:`LoopHistory.squared_xy_aim_errors` measures
        them against what was aimed at.
    """

    max_steps: int = 400
    kick_period_s: float = KICK_WINDOW_S
    settle_rest_steps: int = 3
    stall_kicks: int = 60
    stall_progress_rad: float = 1e-6
    cone_policy: ConePolicy = ConePolicy.CLAMP
    cone_half_angle_rad: float = CONE_HALF_ANGLE_RAD
    preview: bool = True


@dataclasses.dataclass(frozen=True)
class LoopHistory:
    """What happened, step by step.

    Attributes
    ----------
    times_s : ndarray, shape (n + 1,)
    normals : ndarray, shape (n + 1, 3)
        True resting normals.
    used_normals : ndarray, shape (n + 1, 3)
        Normals the controller acted on (measured or estimated).
    references : ndarray, shape (n + 1, 3)
        Reference normals (after clamping).
    aims : ndarray, shape (n, 3)
        The reference normal each step's decision aimed at: its own sample, or with preview
        where the reference's motion at the decision carries it in one kick period.
    actions : ndarray of int, shape (n,)
        Action per step, NO_ACTION when resting.
    intensities : ndarray, shape (n,)
    clamped : ndarray of bool, shape (n + 1,)
    outcome : Outcome
    settle_step : int or None
        Steps until the last rest streak began (SETTLED only).
    """

    times_s: NDArray[np.float64]
    normals: NDArray[np.float64]
    used_normals: NDArray[np.float64]
    references: NDArray[np.float64]
    aims: NDArray[np.float64]
    actions: NDArray[np.int_]
    intensities: NDArray[np.float64]
    clamped: NDArray[np.bool_]
    outcome: Outcome
    settle_step: int | None

    @property
    def errors_rad(self) -> NDArray[np.float64]:
        """True error angle Phi per step (rad), shape (n + 1,)."""
        return np.array([error_angle_rad(n, r) for n, r in
                         zip(self.normals, self.references, strict=True)])

    @property
    def squared_xy_errors(self) -> NDArray[np.float64]:
        """Quadratic x-y deviation from the reference (Fig. 15b), shape (n + 1,)."""
        return np.sum((self.normals[:, :2] - self.references[:, :2]) ** 2, axis=1)

    @property
    def squared_xy_aim_errors(self) -> NDArray[np.float64]:
        """Quadratic x-y deviation of each step's outcome from what its decision aimed at,
        shape (n,): entry k scores state k + 1 (a step at rest aimed too)."""
        return np.sum((self.normals[1:, :2] - self.aims[:, :2]) ** 2, axis=1)

    @property
    def kicks(self) -> int:
        return int(np.count_nonzero(self.actions != NO_ACTION))

    @property
    def kicks_to_settle(self) -> int | None:
        """Kicks applied before settling, or None if the run did not settle."""
        if self.outcome is not Outcome.SETTLED:
            return None
        return int(np.count_nonzero(self.actions[:self.settle_step] != NO_ACTION))

    @property
    def final_error_rad(self) -> float:
        return float(self.errors_rad[-1])

    @property
    def reference_clamped(self) -> bool:
        return bool(self.clamped.any())


def run_closed_loop(controller: Controller, plant: KickPlant,
                    start_normal: ArrayLike, reference: Reference,
                    settings: LoopSettings = LoopSettings(), sensor: NoisySensor | None = None,
                    estimator: NormalKalmanFilter | None = None) -> LoopHistory:
    """Run ``controller`` on ``plant`` from ``start_normal`` towards ``reference``.

    Parameters
    ----------
    controller : sphere_control.command.Controller
    plant : KickPlant
    start_normal : ndarray, shape (3,)
    reference : Setpoint or CircleTrajectory
        Anything with ``xy_at(time_s)`` and ``is_constant``.
    settings : LoopSettings
    sensor : NoisySensor, optional
        Without one the controller sees the true normal.
    estimator : NormalKalmanFilter, optional
        Filters the measurements; the controller acts on (and learns from) its estimate.

    Returns
    -------
    LoopHistory
    """
    true_normal = np.asarray(start_normal, dtype=float)
    trace = _Trace()
    stall = _StallWatch(settings)
    outcome: Outcome | None = None
    settle_step: int | None = None
    rest_streak = 0
    # The node's kick cycle, with this loop as its plant: a kick starts at the sample it was
    # decided on and is over, learnt from, at the next one, a kick period later.
    cycle = KickCycle(controller, settings.kick_period_s, lead_periods=0)

    def measure() -> NDArray[np.float64]:
        seen = true_normal if sensor is None else sensor.measure(true_normal)
        return seen if estimator is None else estimator.update(seen)

    for step in range(settings.max_steps + 1):
        time_s = step * settings.kick_period_s
        sample = ref.sample(reference, time_s, settings.cone_half_angle_rad)
        seen = measure()
        cycle.record(time_s, seen)
        cycle.land()
        trace.state(time_s, true_normal, seen, sample)
        outcome = _stop(settings, reference, sample, stall, true_normal)
        if outcome is not None or step == settings.max_steps:
            break
        aim = _target(settings, reference, sample, time_s).normal
        cycle.on_reference(aim)
        command = cycle.decide().command
        if command is None:
            rest_streak += 1
            trace.action(NO_ACTION, 0.0, aim)
            if reference.is_constant and rest_streak >= settings.settle_rest_steps:
                outcome, settle_step = Outcome.SETTLED, step + 1 - rest_streak
                # the state is the last one recorded; close the history there
                trace.state((step + 1) * settings.kick_period_s, true_normal, seen, sample)
                break
            continue
        rest_streak = 0
        try:
            result = plant.kick(true_normal, command.action, command.intensity)
        except ValueError:  # the plant's model does not reach this far (e.g. TableError)
            outcome = Outcome.PLANT_LIMIT
            break
        cycle.kick_ran(time_s, time_s)
        if estimator is not None:
            estimator.predict(controller.expected_displacement_xy(seen, command))
        true_normal = result.normal
        trace.action(command.action, command.intensity, aim)
        stall.kicked()
    if outcome is None:
        outcome = Outcome.NOT_SETTLED if reference.is_constant else Outcome.COMPLETED
    return trace.history(outcome, settle_step)


def _target(settings: LoopSettings, reference: Reference, sample: ReferenceSample,
            time_s: float) -> ReferenceSample:
    """What the controller aims at: the current sample, or with preview where the reference
    will be one kick period on, when the kick about to be decided has settled, by its motion
    now (:func:`~sphere_control.reference.preview`, as the controller node estimates it)."""
    if not settings.preview or reference.is_constant:
        return sample
    return ref.preview(reference, time_s, settings.kick_period_s, settings.cone_half_angle_rad)


def _stop(settings: LoopSettings, reference: Reference, sample: ReferenceSample,
          stall: _StallWatch, true_normal: NDArray[np.float64]) -> Outcome | None:
    """The outcome that ends a run before its next decision, or None."""
    if sample.clamped and settings.cone_policy is ConePolicy.REFUSE:
        return Outcome.UNREACHABLE
    if reference.is_constant and stall.stalled(error_angle_rad(true_normal, sample.normal)):
        return Outcome.STALLED
    return None


class _Trace:
    """A loop's history as it grows: one state per step, one action between two states."""

    def __init__(self) -> None:
        self.times: list[float] = []
        self.normals: list[NDArray[np.float64]] = []
        self.used: list[NDArray[np.float64]] = []
        self.refs: list[NDArray[np.float64]] = []
        self.clamped: list[bool] = []
        self.actions: list[int] = []
        self.intensities: list[float] = []
        self.aims: list[NDArray[np.float64]] = []

    def state(self, time_s: float, true_normal: NDArray[np.float64], seen: NDArray[np.float64],
              sample: ReferenceSample) -> None:
        self.times.append(time_s)
        self.normals.append(np.array(true_normal, dtype=float))
        self.used.append(seen)
        self.refs.append(sample.normal)
        self.clamped.append(sample.clamped)

    def action(self, action: int, intensity: float, aim: NDArray[np.float64]) -> None:
        self.actions.append(action)
        self.intensities.append(intensity)
        self.aims.append(np.array(aim, dtype=float))

    def history(self, outcome: Outcome, settle_step: int | None) -> LoopHistory:
        keep = len(self.actions) + 1  # a run that stopped mid-step has one state too many
        return LoopHistory(np.array(self.times[:keep]), np.array(self.normals[:keep]),
                           np.array(self.used[:keep]), np.array(self.refs[:keep]),
                           np.array(self.aims).reshape(-1, 3),
                           np.array(self.actions, dtype=int), np.array(self.intensities),
                           np.array(self.clamped[:keep]), outcome, settle_step)


class _StallWatch:
    """A setpoint run stalls when ``stall_kicks`` kicks bring no progress of more than
    ``stall_progress_rad`` on its best error."""

    def __init__(self, settings: LoopSettings) -> None:
        self.settings = settings
        self.best_error = math.inf
        self.kicks_since_best = 0

    def stalled(self, error: float) -> bool:
        if error < self.best_error - self.settings.stall_progress_rad:
            self.best_error, self.kicks_since_best = error, 0
            return False
        return self.kicks_since_best >= self.settings.stall_kicks

    def kicked(self) -> None:
        self.kicks_since_best += 1
