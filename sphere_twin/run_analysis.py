"""What a recorded run says: surface-normal error against time, kicks, settle times, and the
open-loop replay of its commands through the twin.

Works on any bag of the contract's topics (ours or one made by ``ros2 bag record``). Times are
the surface-normal samples' header stamps (simulated time in a twin's bag, wall time on the
device). A programme starts where the device's report on ``/beams/programme_status`` says it
started (a refused one never ran); in a bag without reports, at its own stamp, or on receipt if
it has none. References and voltage commands are placed by their receive time, mapped onto the
stamps of the samples received around it, since the node that sent them may stamp with another
clock.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import os
import time
from collections.abc import Callable, Iterable, Iterator, Sequence
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from msg_defs.conversions import (
    LEGACY_PROGRAMME_STATUS_TYPE,
    legacy_programme_status_from_cdr,
    ns_from_time,
    programme_events_from_msg,
    programme_from_msg,
    status_values,
    surface_normal_from_msg,
    voltages_from_msg,
)
from msg_defs.device import NS_PER_S
from msg_defs.programme_events import ProgrammeState
from msg_defs.topics import (
    CONTROLLER_STATUS,
    DIAGNOSTICS,
    PROGRAMME_STATUS,
    PULSE_PROGRAM,
    SPHERE_REFERENCE,
    SURFACE_NORMAL,
    VOLTAGE_COMMAND,
)
from msg_defs.voltage_rules import check_segments, check_voltages
from sphere_control.reference_motion import JUMP_TOLERANCE
from sphere_sim.model.rotations import angle_between
from sphere_sim.twin.plants import TIME_TOL_S
from sphere_twin.bag.reader import (
    BagError,
    deserialize,
    has_footer,
    read_messages,
    read_metadata,
    scan_mcap,
    storage_files,
)

if TYPE_CHECKING:
    from pathlib import Path

    from msg_defs.programme_events import ProgrammeEvent
    from sphere_sim.kicks.lookup_table import CombinedKickPlant, LookupTable
    from sphere_sim.model.initial_state import Relaxation
    from sphere_sim.model.parameters import ParameterSet
    from sphere_sim.twin.plants import TwinPlant

# (start_s, times_s (k,), voltages_v (k, 4)) of a programme; (time_s, voltages_v (4,)) of a hold.
Kick = tuple[float, NDArray[np.float64], NDArray[np.float64]]
Hold = tuple[float, NDArray[np.float64]]
# What replay() feeds the plant: a programme's segments or a hold's voltages.
_ReplayEvent = (tuple[Literal['programme'], NDArray[np.float64], NDArray[np.float64]]
                | tuple[Literal['hold'], NDArray[np.float64]])

DEFAULT_BAND_RAD = math.radians(0.05)  # Fig. 13's tighter resting band
# A reference held at least this long counts as a setpoint whose settling time is reported.
MIN_SETPOINT_S = 0.5
# The controller's phases in which it decided on a sample (sphere_control.kick_cycle.Phase).
DECIDING_PHASES = ('kicking', 'resting')
# Wall seconds between two progress lines of a long command: often enough that it never seems
# to hang (the promise is one at least every 10 s), seldom enough not to bury its results.
PROGRESS_PERIOD_S = 5.0


class ProgressClock:
    """Says when a long loop's next progress line is due: once per ``period_s`` of wall time,
    the first one ``period_s`` after it was made (a short run prints none)."""

    def __init__(self, period_s: float | None = None) -> None:
        self.period_s = PROGRESS_PERIOD_S if period_s is None else period_s
        self._next_s = time.monotonic() + self.period_s

    def due(self) -> bool:
        now_s = time.monotonic()
        if now_s < self._next_s:
            return False
        self._next_s = now_s + self.period_s
        return True


@dataclasses.dataclass(frozen=True)
class RecordedRun:
    """The contract's signals of one bag, on the stamp time base.

    Attributes
    ----------
    normal_t_s : ndarray, shape (n,)
    normals : ndarray, shape (n, 3)
        Measured surface normals.
    reference_t_s : ndarray, shape (m,)
    references : ndarray, shape (m, 3)
    kicks : list of (time_s, times_s (k,), voltages_v (k, 4))
        Pulse programmes: start time and zero-order-hold segments.
    holds : list of (time_s, voltages_v (4,))
        Voltage commands.
    decision_t_s : ndarray, shape (d,)
        Stamps of the samples the controller decided on (a kick or a rest; none while a kick
        was in effect), from ``/controller/status``: where its loop saw a settled state.
    """

    normal_t_s: NDArray[np.float64]
    normals: NDArray[np.float64]
    reference_t_s: NDArray[np.float64]
    references: NDArray[np.float64]
    kicks: list[Kick]
    holds: list[Hold]
    decision_t_s: NDArray[np.float64] = dataclasses.field(default_factory=lambda: np.zeros(0))


class _Messages:
    """A bag's contract messages by kind, as read (stamps and receive times, unsorted)."""

    TOPICS = (SURFACE_NORMAL.name, SPHERE_REFERENCE.name, PULSE_PROGRAM.name,
              VOLTAGE_COMMAND.name, PROGRAMME_STATUS.name, CONTROLLER_STATUS.name)

    def __init__(self) -> None:
        self.normals: list[tuple[float, NDArray[np.float64]]] = []
        self.references: list[tuple[int, NDArray[np.float64]]] = []
        # (log_time_ns, stamp_ns, times_s, voltages_v)
        self.programmes: list[tuple[int, int, NDArray[np.float64], NDArray[np.float64]]] = []
        self.holds: list[tuple[int, NDArray[np.float64]]] = []
        self.reports: list[ProgrammeEvent] = []
        self.decisions: list[float] = []
        self.receive_map: list[tuple[int, float]] = []  # (log_time_ns, stamp_s) of the normals

    def add(self, topic: str, log_time_ns: int, msg: Any) -> None:
        """File one message; ValueError for one that breaks the contract."""
        if topic == SURFACE_NORMAL.name:
            t = ns_from_time(msg.header.stamp) / NS_PER_S
            self.normals.append((t, surface_normal_from_msg(msg)))
            self.receive_map.append((log_time_ns, t))
        elif topic == SPHERE_REFERENCE.name:
            self.references.append((log_time_ns, surface_normal_from_msg(msg)))
        elif topic == PULSE_PROGRAM.name:
            self.programmes.append((log_time_ns, ns_from_time(msg.header.stamp),
                                    *check_segments(*programme_from_msg(msg))))
        elif topic == PROGRAMME_STATUS.name:
            self.reports.extend(programme_events_from_msg(msg))
        elif topic == CONTROLLER_STATUS.name:
            values = status_values(msg.status[0])
            if 'decided_s' in values:
                self.decisions.extend(float(t) for t in values['decided_s'].split())
            elif values.get('phase') in DECIDING_PHASES:
                # Recorded before the status was batched: one status per decision.
                self.decisions.append(ns_from_time(msg.header.stamp) / NS_PER_S)
        else:
            self.holds.append((log_time_ns, check_voltages(voltages_from_msg(msg))))


# What a device itself records: its commands and its sensor (and the reference it was given).
# Identification reads only these; the twin's reports and the controller's status are extras.
DEVICE_TOPICS = (SURFACE_NORMAL.name, SPHERE_REFERENCE.name, PULSE_PROGRAM.name,
                 VOLTAGE_COMMAND.name)


def load_run(bag_dir: str | os.PathLike[str],
             topics: Iterable[str] = _Messages.TOPICS) -> RecordedRun:
    """Read the contract's signals from a bag; BagError if it has no surface normal.

    ``topics`` limits what is read (:data:`DEVICE_TOPICS`: only what the device records);
    without the programme reports, programmes start at their stamps.
    """
    read = _Messages()
    for raw in read_messages(bag_dir, list(topics)):
        try:
            read.add(raw.topic, raw.log_time_ns,
                     legacy_programme_status_from_cdr(raw.data)
                     if raw.type_name == LEGACY_PROGRAMME_STATUS_TYPE else deserialize(raw))
        except ValueError:
            # A message that breaks the contract or the command rules: the twin refused it too.
            continue
    if not read.normals:
        raise BagError(f'{bag_dir}: no {SURFACE_NORMAL.name} messages to analyse')
    log_ns = np.array([m[0] for m in read.receive_map], dtype=float)
    stamps = np.array([m[1] for m in read.receive_map])

    def on_stamps(log_time_ns: float) -> float:
        return float(np.interp(log_time_ns, log_ns, stamps))

    normals = sorted(read.normals, key=lambda item: item[0])
    # A reference is in force from when it arrives (its node may stamp with another clock).
    references = sorted(((on_stamps(log), n) for log, n in read.references),
                        key=lambda r: r[0])
    def at_stamp(log_ns: int, stamp_ns: int) -> float:
        return stamp_ns / NS_PER_S if stamp_ns else on_stamps(log_ns)

    kicks = sorted(_reported_starts(read.programmes, read.reports, at_stamp),
                   key=lambda k: k[0])
    return RecordedRun(
        np.array([t for t, _ in normals]), np.array([n for _, n in normals]),
        np.array([t for t, _ in references]), np.array([n for _, n in references]).reshape(-1, 3),
        kicks, sorted(((on_stamps(log), volts) for log, volts in read.holds),
                      key=lambda h: h[0]),
        np.unique(read.decisions))


def unclosed_bag_warning(bag_dir: str | os.PathLike[str], run: RecordedRun) -> str | None:
    """What a command that analysed ``run``, read from ``bag_dir``, must say when a file of the
    bag was not closed (its recorder died): that it read only the readable part, how much
    that was, and the command that closes the bag; None for a bag closed cleanly.

    The readable part is every chunk completed before the end, exactly what ``bag repair``
    keeps, so the analysis is the one the repaired bag would give: the commands go on with
    this warning rather than refuse (``bag info`` tells the same story).
    """
    unclosed = [scan_mcap(path) for path in storage_files(bag_dir) if not has_footer(path)]
    if not unclosed:
        return None
    reasons = '; '.join(f'{scan.path.name}: {scan.stop_reason}' for scan in unclosed)
    read = sum(len(scan.messages) for scan in unclosed)
    # A recorder rewrites metadata.yaml as it goes or only at the end: a count is a fact
    # only if it is more than what was read.
    listed = read_metadata(bag_dir).get('message_count') or 0
    of_listed = f' of the {listed} messages metadata.yaml lists' if listed > read else ' messages'
    return (f'{bag_dir} was not closed ({reasons}): read only its readable part, {read}'
            f'{of_listed}, surface normals from {run.normal_t_s[0]:.2f} to '
            f'{run.normal_t_s[-1]:.2f} s; run `sphere-twin bag repair {bag_dir}` to close it')


def _reported_starts(programmes: Sequence[tuple[int, int, NDArray[np.float64],
                                                NDArray[np.float64]]],
                     reports: Iterable[ProgrammeEvent],
                     unreported_start_s: Callable[[int, int], float]) -> list[Kick]:
    """(start_s, times, volts) of the programmes that ran: at the start the device reported,
    a refused one not at all, and one whose report was not recorded (a recorder that joined
    the topic late) at ``unreported_start_s(log_time_ns, stamp_ns)``. A report names its
    programme by the stamp it was sent with; programmes that share a stamp (0: at once) are
    matched in the order they were received."""
    # stamp in ns -> [start_s or None (refused)], in report order
    outcomes: dict[int, list[float | None]] = {}
    for event in reports:
        if event.state in (ProgrammeState.STARTED, ProgrammeState.REFUSED):
            outcomes.setdefault(round(event.asked_s * NS_PER_S), []).append(
                event.time_s if event.state is ProgrammeState.STARTED else None)
    kicks: list[Kick] = []
    for log_ns, stamp_ns, times, volts in sorted(programmes, key=lambda p: p[0]):
        queue = outcomes.get(stamp_ns)
        start_s = queue.pop(0) if queue else unreported_start_s(log_ns, stamp_ns)
        if start_s is not None:
            kicks.append((start_s, times, volts))
    return kicks


# Two reference samples further apart than this (s) are not interpolated between: the
# reference node publishes at 10 Hz, and a longer gap is a pause or a lost stretch.
REFERENCE_INTERPOLATION_MAX_GAP_S = 0.25


def reference_at(run: RecordedRun, times_s: ArrayLike) -> NDArray[np.float64]:
    """The reference at each time (NaN before the first sample), shape (len(times_s), 3).

    A moving reference is scored where it is at the sample's time, as the paper's Fig. 15b and
    the offline loop score it, not where its last sample was (at 10 Hz that sample can be a
    tenth of a second old, a few kick periods of eq. (64)). Between two samples received close
    together that continue the step before them (within the controller's jump tolerance,
    :data:`~sphere_control.reference_motion.JUMP_TOLERANCE`) the reference is interpolated;
    after the last sample, across a longer gap, and from a jump until the next sample, the
    newest one holds, so a jump is never spread back in time.
    """
    times_s = np.asarray(times_s, dtype=float)
    out = np.full((len(times_s), 3), np.nan)
    t_ref, refs = run.reference_t_s, run.references
    if t_ref.size == 0:
        return out
    index = np.searchsorted(t_ref, times_s, side='right') - 1
    valid = index >= 0
    out[valid] = refs[index[valid]]
    smooth = _continuing_intervals(t_ref, refs)
    between = valid & (index < t_ref.size - 1)
    between[between] = smooth[index[between]]
    if between.any():
        i = index[between]
        w = ((times_s[between] - t_ref[i]) / (t_ref[i + 1] - t_ref[i]))[:, None]
        mixed = (1.0 - w) * refs[i] + w * refs[i + 1]
        out[between] = mixed / np.linalg.norm(mixed, axis=1)[:, None]
    return out


def _continuing_intervals(t_ref: NDArray[np.float64],
                          refs: NDArray[np.float64]) -> NDArray[np.bool_]:
    """Per interval (i, i + 1) of the reference samples, shape (n - 1,): True where the step
    continues the one before it (no jump) and the gap is short."""
    n = t_ref.size
    smooth = np.zeros(max(n - 1, 0), dtype=bool)
    if n < 3:
        return smooth
    dt = np.diff(t_ref)
    step = np.diff(refs[:, :2], axis=0)
    with np.errstate(divide='ignore', invalid='ignore'):
        expected = step[:-1] * (dt[1:] / dt[:-1])[:, None]
    off = np.hypot(*(step[1:] - expected).T)
    smooth[1:] = ((dt[1:] > 0.0) & (dt[:-1] > 0.0) & (off <= JUMP_TOLERANCE)
                  & (dt[1:] <= REFERENCE_INTERPOLATION_MAX_GAP_S))
    return smooth


@dataclasses.dataclass(frozen=True)
class RunStatistics:
    kicks: int
    duration_s: float
    final_error_rad: float
    rms_error_rad: float
    max_error_rad: float
    # per setpoint: time until the error stays within the band (or None)
    settle_times_s: list[float | None]
    band_rad: float
    # RMS error at the samples the controller decided on (settled states, as the offline loop
    # records them); NaN for a bag without the controller's status.
    rms_decided_error_rad: float = math.nan

    def to_dict(self) -> dict[str, Any]:
        return {'kicks': self.kicks, 'duration_s': self.duration_s,
                'final_error_deg': math.degrees(self.final_error_rad),
                'rms_error_deg': math.degrees(self.rms_error_rad),
                'max_error_deg': math.degrees(self.max_error_rad),
                'settle_times_s': self.settle_times_s, 'band_deg': math.degrees(self.band_rad),
                'rms_decided_error_deg': (math.degrees(self.rms_decided_error_rad)
                                          if math.isfinite(self.rms_decided_error_rad)
                                          else None)}


def errors_rad(run: RecordedRun) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(times_s, error_rad) of the samples that have a reference (:func:`reference_at`)."""
    refs = reference_at(run, run.normal_t_s)
    valid = ~np.isnan(refs[:, 0])
    errors = np.array([angle_between(n, r) for n, r in zip(run.normals[valid], refs[valid],
                                                             strict=True)])
    return run.normal_t_s[valid], errors


def errors_at_decisions_rad(run: RecordedRun,
                            ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(times_s, error_rad) of the samples the controller decided on: the loop's error
    where it saw a settled state, as the offline closed loop records it (one per decision)."""
    times, errors = errors_rad(run)
    if times.size == 0:
        return times, errors
    index = np.clip(np.searchsorted(times, run.decision_t_s - 1e-9), 0, times.size - 1)
    index = index[np.abs(times[index] - run.decision_t_s) < 1e-6]  # a recorded sample
    return times[index], errors[index]


def setpoint_segments(run: RecordedRun,
                      min_duration_s: float = MIN_SETPOINT_S) -> list[tuple[float, float]]:
    """(start_s, end_s) of the stretches over which the reference stays the same."""
    if run.reference_t_s.size == 0:
        return []
    segments: list[tuple[float, float]] = []
    start = 0
    for i in range(1, run.reference_t_s.size + 1):
        if i == run.reference_t_s.size or angle_between(run.references[i],
                                                        run.references[start]) > 1e-12:
            end_s = run.reference_t_s[i] if i < run.reference_t_s.size else run.normal_t_s[-1]
            if end_s - run.reference_t_s[start] >= min_duration_s:
                segments.append((float(run.reference_t_s[start]), float(end_s)))
            start = i
    return segments


def statistics(run: RecordedRun, band_rad: float = DEFAULT_BAND_RAD) -> RunStatistics:
    times, errors = errors_rad(run)
    if errors.size == 0:
        raise BagError('no surface normal was recorded while a reference was in force')
    settle: list[float | None] = []
    for start_s, end_s in setpoint_segments(run):
        inside = (times >= start_s) & (times <= end_s)
        seg_t, seg_e = times[inside], errors[inside]
        outside = np.flatnonzero(seg_e > band_rad)
        if outside.size == 0:
            settle.append(0.0)
        elif outside[-1] + 1 < seg_t.size:
            settle.append(float(seg_t[outside[-1] + 1] - start_s))
        else:
            settle.append(None)  # never settled within the segment
    _, decided = errors_at_decisions_rad(run)
    return RunStatistics(len(run.kicks), float(run.normal_t_s[-1] - run.normal_t_s[0]),
                         float(errors[-1]), float(np.sqrt(np.mean(errors ** 2))),
                         float(errors.max()), settle, band_rad,
                         float(np.sqrt(np.mean(decided ** 2))) if decided.size else math.nan)


def plot_report(run: RecordedRun, path: str | os.PathLike[str],
                title: str = '') -> str | os.PathLike[str]:
    """Error against time with the kicks marked (ticks, or a rate where they are dense), and
    the x-y path in degrees of tilt beside the setpoints and the reference trajectory."""
    from sphere_twin.plots import SAVE_DPI, draw_kicks, draw_tilt_path, legend_of, plt

    times, errors = errors_rad(run)
    fig, (ax_err, ax_xy) = plt.subplots(1, 2, figsize=(11.5, 4.6))
    ax_err.semilogy(times, np.maximum(np.degrees(errors), 1e-6), lw=1, label='error')
    span = (float(run.normal_t_s[0]), float(run.normal_t_s[-1]))
    marks_ax = draw_kicks(ax_err, [k[0] for k in run.kicks], span)
    ax_err.set_xlabel('time (s)')
    ax_err.set_ylabel('angle to reference (deg)')
    ax_err.grid(alpha=0.3, which='both')
    legend_of(ax_err, marks_ax, fontsize=8)
    setpoints, trajectory = reference_parts(run)
    draw_tilt_path(ax_xy, run.normals, setpoints, trajectory)
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=SAVE_DPI)
    plt.close(fig)
    return path


def reference_parts(run: RecordedRun) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(setpoints (k, 3), trajectory (m, 3)): the reference held over each setpoint segment,
    and the references received outside them (a moving reference), in order."""
    segments = setpoint_segments(run)
    held = np.zeros(run.reference_t_s.shape, dtype=bool)
    for start_s, end_s in segments:
        held |= (run.reference_t_s >= start_s) & (run.reference_t_s < end_s)
    starts = [int(np.searchsorted(run.reference_t_s, start_s)) for start_s, _ in segments]
    return run.references[starts].reshape(-1, 3), run.references[~held].reshape(-1, 3)


@dataclasses.dataclass(frozen=True)
class ReplayResult:
    times_s: NDArray[np.float64]
    error_rad: NDArray[np.float64]  # simulated against recorded normal at each recorded sample

    @property
    def max_error_rad(self) -> float:
        return float(self.error_rad.max()) if self.error_rad.size else 0.0

    @property
    def rms_error_rad(self) -> float:
        return float(np.sqrt(np.mean(self.error_rad ** 2))) if self.error_rad.size else 0.0


# How a bag's physics was integrated where its simulator did not say (its status carries
# ``integration_method`` since the live twin's method could be other than the studies'): the
# compiled Radau, which every earlier twin ran.
UNSTATED_INTEGRATION_METHOD = 'fast'


def recorded_integration_method(bag_dir: str | os.PathLike[str]) -> str:
    """The integration method the simulator that recorded ``bag_dir`` said it ran (its status
    on ``/diagnostics``), or ``UNSTATED_INTEGRATION_METHOD``."""
    for raw in read_messages(bag_dir, [DIAGNOSTICS.name]):
        try:
            msg = deserialize(raw)
        except ValueError:
            continue
        for status in msg.status:
            method = status_values(status).get('integration_method')
            if status.name.startswith('simulator') and method:
                return method
    return UNSTATED_INTEGRATION_METHOD


def build_replay_plant(kind: str, normal0: NDArray[np.float64], time0_s: float,
                       params: ParameterSet, tables: Iterable[str | Path] = (),
                       relaxation: Relaxation | None = None,
                       truth: TruthSample | None = None,
                       method: str = UNSTATED_INTEGRATION_METHOD) -> TwinPlant:
    """A plant of parameter set ``params`` resting at ``normal0`` at ``time0_s``: the kick
    table's (``kind`` 'discrete') or the physics at the live tolerance, from the rest state
    at the normal's cardan angles (relaxed by ``relaxation``, see
    :func:`~sphere_sim.model.initial_state.rest_state`).

    Given ``truth`` (a twin's bag records it), the physics starts from the recorded sphere and
    beams instead, their positions and rates; only the bristles' strain, which no topic
    carries, is the rest's at the recorded sphere's normal. The physics is integrated by
    ``method`` (:func:`recorded_integration_method`)."""
    from sphere_sim.kicks.design import cardan_of_normal
    from sphere_sim.kicks.process_models import process_model
    from sphere_sim.model.initial_state import rest_state
    from sphere_sim.twin.plant_setup import discrete_plant
    from sphere_sim.twin.plants import ContinuousPlant

    paths = tuple(str(path) for path in tables)
    plant: TwinPlant
    if kind == 'discrete':
        plant = discrete_plant(_kick_model(paths, params), normal0)
    else:
        model = process_model(params)
        rest_normal = normal0 if truth is None else truth.normal
        x0 = rest_state(model, cardan_of_normal(rest_normal), relaxation=relaxation)
        plant = ContinuousPlant(model, x0 if truth is None else truth.state_of(model, x0),
                                kick_period_s=replay_kick_period_s(paths), method=method)
    plant.time_s = time0_s
    return plant


@dataclasses.dataclass(frozen=True)
class TruthSample:
    """The sphere's and the beams' state at one sample, as a twin's bag records them
    (``/sphere/state``, ``/beams/state``).

    Attributes
    ----------
    sphere : ndarray, shape (13,)
        Centre (m), quaternion (w, x, y, z), centre velocity in ``world`` (m/s), angular
        velocity in ``sphere`` (rad/s): the model's sphere state.
    beams : ndarray, shape (16,)
        z (m) and phi (rad) of beam 1..4 interleaved, then their rates likewise: the model's
        beam states.
    """

    sphere: NDArray[np.float64]
    beams: NDArray[np.float64]

    @property
    def normal(self) -> NDArray[np.float64]:
        from sphere_sim.model.rotations import quat_to_matrix

        q = self.sphere[3:7] / np.linalg.norm(self.sphere[3:7])
        return quat_to_matrix(np.ascontiguousarray(q))[:, 2].copy()

    def state_of(self, model: Any, x: NDArray[np.float64]) -> NDArray[np.float64]:
        """``x`` (a state of ``model``, a :class:`~sphere_sim.model.assembly.Model` with the
        sphere and four beams) with the recorded sphere and beams in place of its own."""
        n = model.n_beams
        if 4 * n != self.beams.size:
            raise ValueError(f'the recording has {self.beams.size // 4} beams, the model {n}')
        x = np.array(x, dtype=float)
        x[:4 * n] = self.beams
        x[model.sphere_offset:model.sphere_offset + 13] = self.sphere
        return x


@dataclasses.dataclass(frozen=True)
class RecordedTruth:
    """A twin's bag's record of its sphere and beams (a device's bag has none): the samples
    where both topics carry the full state, rates included, by stamp."""

    t_s: NDArray[np.float64]
    samples: tuple[TruthSample, ...]

    def at(self, time_s: float) -> TruthSample | None:
        """The sample stamped ``time_s`` (within ``TIME_TOL_S``), or None."""
        i = int(np.searchsorted(self.t_s, time_s - TIME_TOL_S))
        return (self.samples[i] if i < self.t_s.size and abs(self.t_s[i] - time_s) <= TIME_TOL_S
                else None)


def load_truth(bag_dir: str | os.PathLike[str]) -> RecordedTruth | None:
    """The sphere's and the beams' recorded state (:class:`RecordedTruth`), or None where the
    bag holds no sample with both (a device's, or the discrete plant's without rates)."""
    from msg_defs.conversions import (
        beam_rates_from_msg,
        beam_state_from_msg,
        sphere_state_from_msg,
        sphere_twist_from_msg,
    )
    from msg_defs.topics import BEAM_STATE, SPHERE_STATE

    spheres: dict[int, NDArray[np.float64]] = {}
    beams: dict[int, NDArray[np.float64]] = {}
    for raw in read_messages(bag_dir, [SPHERE_STATE.name, BEAM_STATE.name]):
        try:
            msg = deserialize(raw)
            stamp_ns = ns_from_time(msg.header.stamp)
            if raw.topic == SPHERE_STATE.name:
                spheres[stamp_ns] = np.concatenate([*sphere_state_from_msg(msg),
                                                    *sphere_twist_from_msg(msg)])
            else:
                rates = beam_rates_from_msg(msg)
                if rates is not None:
                    positions = np.ravel(np.column_stack(beam_state_from_msg(msg)))
                    beams[stamp_ns] = np.concatenate([positions, np.ravel(np.column_stack(rates))])
        except ValueError:
            continue  # a message that breaks the contract: no state there
    stamps = sorted(set(spheres) & set(beams))
    if not stamps:
        return None
    return RecordedTruth(np.array(stamps, dtype=float) / NS_PER_S,
                         tuple(TruthSample(spheres[t], beams[t]) for t in stamps))


def replay_kick_period_s(tables: Iterable[str | Path] = ()) -> float:
    """How long after its start a programme's effect is over on a replay's plant: the kick
    period of its tables (:func:`~sphere_sim.kicks.discrete.kick_period_s`), which the
    simulator's plants use too."""
    from sphere_sim.kicks.discrete import kick_period_s

    return kick_period_s(_kick_model(tuple(str(path) for path in tables), None))


@functools.lru_cache(maxsize=4)
def _kick_model(paths: tuple[str, ...],
                params: ParameterSet | None) -> LookupTable | CombinedKickPlant:
    """The kick tables, loaded once per process: a replay one kick ahead builds a plant for
    every kick, on every worker."""
    from sphere_sim.kicks.lookup_table import load_kick_model

    return load_kick_model(paths, params)


def replay_start_index(run: RecordedRun, window_s: float) -> int:
    """First sample from which a replay can start: no kick recorded before it still acting."""
    t0 = run.normal_t_s[0]
    earlier = [t for t, _, _ in run.kicks if t < t0]
    if not earlier:
        return 0
    return int(np.searchsorted(run.normal_t_s, max(earlier) + window_s - TIME_TOL_S))


def replay(run: RecordedRun, plant: TwinPlant, start_index: int = 0,
           progress: Callable[[float], None] | None = None) -> ReplayResult:
    """Feed the recorded commands open loop into ``plant``, sampled at the recorded times.

    The plant starts from the recorded normal at ``start_index`` (the caller builds it so;
    see :func:`replay_start_index` for a bag whose recording began mid-kick); each programme
    starts at its stamp, each voltage command at its mapped receive time. ``progress`` is
    called with each sample's time once the plant has reached it (a long replay's progress).
    """
    t0 = run.normal_t_s[start_index]
    times = run.normal_t_s[start_index:]
    errors: list[float] = []
    for t, simulated, recorded in zip(times, replayed_normals(plant, times, run.kicks,
                                                              run.holds, t0),
                                      run.normals[start_index:], strict=True):
        errors.append(angle_between(simulated, recorded))
        if progress is not None:
            progress(float(t))
    return ReplayResult(times.copy(), np.array(errors))


def replayed_normals(plant: TwinPlant, times_s: Iterable[float], kicks: Iterable[Kick],
                     holds: Iterable[Hold], from_s: float) -> Iterator[NDArray[np.float64]]:
    """The normal of ``plant`` at each of ``times_s`` (ascending), the recorded commands from
    ``from_s`` on fed in as they fall due: a programme at its start, a voltage command at its
    time, a programme before a voltage command at the same time. A command the plant refuses
    is skipped, as the device's twin refused it when live."""
    from sphere_sim.model.programme import PulseProgramme
    from sphere_sim.twin.plants import PlantError

    events: list[tuple[float, int, _ReplayEvent]] = sorted(
                    [(t, 0, ('programme', times, volts)) for t, times, volts in kicks
                     if t >= from_s - TIME_TOL_S]
                    + [(t, 1, ('hold', volts)) for t, volts in holds if t >= from_s],
                    key=lambda e: (e[0], e[1]))
    k = 0
    for t in times_s:
        while k < len(events) and events[k][0] <= t + TIME_TOL_S:
            at, _, event = events[k]
            plant.advance(max(at, plant.time_s))
            try:
                if event[0] == 'programme':
                    plant.run_programme(PulseProgramme.from_segments(event[1], event[2]))
                else:
                    plant.hold(event[1])
            except PlantError:
                pass  # refused on the device's twin as well
            k += 1
        plant.advance(max(t, plant.time_s))
        yield plant.snapshot().normal
