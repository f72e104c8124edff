"""The simulator's clock and command handling, free of ROS.

:class:`TwinRunner` owns a plant, the simulated time grid, the queue of commands, the
measurement noise and the lockstep rule; the simulator node only converts messages and calls
it. Every command is checked here against the device's rules (:mod:`msg_defs.voltage_rules`),
where it enters the twin, and a rejected one leaves the plant untouched. What happens to each
programme (started, ended, cut, refused) is kept as a :class:`ProgrammeEvent` for the node to
echo, so that a controller times its kicks by what the twin did.
"""

import collections
import dataclasses
import threading
import time
import typing
from collections.abc import Iterable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from msg_defs.device import VOLTAGE_LIMIT_V
from msg_defs.programme_events import ProgrammeEvent, ProgrammeState
from msg_defs.voltage_rules import VoltageRuleError, check_voltages
from sphere_sim.model.programme import ProgrammeError, PulseProgramme
from sphere_sim.twin.fidelity_check import FidelityCheck
from sphere_sim.twin.plants import TIME_TOL_S, PlantError, PlantSnapshot, TwinPlant

# A programme may start at most this far after the simulated now. Stamps are simulated time;
# one far ahead is a wall-clock stamp (`stamp: now` in `ros2 topic pub`), which would wait
# decades of simulated time: refused, with a message that says so.
MAX_START_AHEAD_S = 60.0
# Commands waiting for their start; a publisher that floods the twin with future programmes
# is refused beyond this, so the queue (and the node's memory) stays bounded.
MAX_QUEUED_COMMANDS = 100
# Latencies kept for the status's median and maximum: the most recent ones, memory bounded.
LATENCY_HISTORY = 10_000


class _Queued(typing.NamedTuple):
    """A command waiting for its sample: when it applies, what it is, and for the accounts
    the start it asked for and when it arrived (wall s)."""

    start_s: float
    kind: str  # 'hold' or 'programme'
    payload: NDArray[np.float64] | PulseProgramme  # the voltages held, or the programme
    asked_s: float
    arrival_wall_s: float
    number: int = 0  # programmes: the runner's count of those received


class _Running(typing.NamedTuple):
    """The programme on the beams: who it is and when its segments end."""

    asked_s: float
    number: int
    end_s: float


class CommandRejectedError(ValueError):
    """A command that breaks the contract or the plant's limits; nothing was changed."""


@dataclasses.dataclass(frozen=True)
class Sample:
    """One published instant: the true snapshot, the measured (noisy) normal, and the
    arrival times (wall s) of the programmes that this sample is the first to show."""

    snapshot: PlantSnapshot
    measured_normal: NDArray[np.float64]
    acted_arrivals_wall_s: tuple[float, ...] = ()


@dataclasses.dataclass
class TwinCounters:
    """What became of every command (voltage command or programme).

    Each one the twin received ends as exactly one of ``accepted`` (applied to the plant),
    ``rejected`` (refused, by the contract, the rules or the plant), ``replaced`` (dropped: a
    newer voltage command superseded it before the plant held it) or is still waiting for its
    sample (:attr:`TwinRunner.waiting`). ``lost`` counts the commands that never reached the
    twin (dropped in the transport's queue); they are not in ``received``. The node books
    ``received``, ``lost`` and the refusals it makes before the runner sees a command.
    """

    samples: int = 0
    received: int = 0
    accepted: int = 0
    rejected: int = 0
    replaced: int = 0
    lost: int = 0
    programmes: int = 0
    late: int = 0  # programmes whose start time had passed when they arrived
    cut: int = 0  # programmes a later voltage command cut short or dropped

    @property
    def dropped(self) -> int:
        """Commands that were neither applied nor refused: replaced or lost."""
        return self.replaced + self.lost


@dataclasses.dataclass
class TwinTimings:
    """Where a run's wall time went, and how long programmes took to act (s).

    ``integrating_s`` is the plant's own time (its ``advance``). A programme's latency is from
    its arrival (``command_programme``) to the publication of the first sample that shows its
    effect, in wall time, and from the start it asked for to the start it got, in simulated
    time. Latencies are recorded by whichever thread publishes, so they are kept under a lock.
    """

    integrating_s: float = 0.0
    latencies_wall_s: collections.deque[float] = dataclasses.field(
        default_factory=lambda: collections.deque(maxlen=LATENCY_HISTORY))
    delays_sim_s: collections.deque[float] = dataclasses.field(
        default_factory=lambda: collections.deque(maxlen=LATENCY_HISTORY))
    _lock: threading.Lock = dataclasses.field(default_factory=threading.Lock, repr=False)

    def record_published(self, sample: Sample, published_wall_s: float) -> None:
        """Book the latencies of the programmes ``sample`` is the first to show, now that it
        is out (``published_wall_s``, ``time.perf_counter()``)."""
        with self._lock:
            self.latencies_wall_s.extend(published_wall_s - arrival
                                         for arrival in sample.acted_arrivals_wall_s)

    def latency_summary(self) -> tuple[float, float]:
        """(median, largest) wall latency in s; NaNs before the first programme."""
        with self._lock:
            latencies = list(self.latencies_wall_s)
        if not latencies:
            return float('nan'), float('nan')
        return float(np.median(latencies)), float(max(latencies))

    def delay_median_s(self) -> float:
        """Median simulated delay of a programme's start after the start it asked for (s)."""
        return float(np.median(self.delays_sim_s)) if self.delays_sim_s else float('nan')


class TwinRunner:
    """Advance a plant on a fixed grid of sample times and apply commands between samples.

    Parameters
    ----------
    plant : sphere_sim.twin.plants.TwinPlant
    period_s : float
        Simulated time between samples.
    noise_std_rad : float
        Standard deviation of the measured normal's error, per tangential axis (rad).
    seed : int
        Seed of the measurement noise.
    lockstep : bool
        If true, time advances only while a command is in effect (until the plant's
        ``busy_until_s``): each command is answered by the samples of its effect and the
        settled sample, and the run is the same whatever the wall-clock timing.
    voltage_limit_v : float
    check : FidelityCheck, optional
        Runs the full model beside the plant on every programme the plant starts, and compares
        the landings (``check_fidelity``).
    """

    def __init__(self, plant: TwinPlant, period_s: float, noise_std_rad: float = 0.0,
                 seed: int = 0, lockstep: bool = False,
                 voltage_limit_v: float = VOLTAGE_LIMIT_V,
                 check: FidelityCheck | None = None) -> None:
        self.plant = plant
        self.check = check
        # Sample times are counted from the last change of period, not summed: no drift.
        self._grid_origin_s = 0.0
        self._step = 0
        self.set_period(period_s)
        self.set_noise(noise_std_rad)
        self.rng = np.random.default_rng(seed)
        self.lockstep = lockstep
        self.voltage_limit_v = voltage_limit_v
        self.counters = TwinCounters()
        self.timings = TwinTimings()
        # In start order, applied at the sample boundary they are due.
        self._queued: list[_Queued] = []
        self._acted: list[float] = []  # (arrival_wall_s) of programmes applied in this tick
        # Until its end is reported or it is cut.
        self._running: _Running | None = None
        self._received = 0  # programmes received, refused ones included
        self._events: list[ProgrammeEvent] = []  # not yet taken by take_events()
        self._idle_published = False

    @property
    def time_s(self) -> float:
        return self._grid_origin_s + self._step * self.period_s

    def set_period(self, period_s: float) -> None:
        """Sample every ``period_s`` from now on (the node's publish rate, set at run time)."""
        if not (np.isfinite(period_s) and period_s > 0):
            raise ValueError(f'period_s must be a positive number, got {period_s}')
        if self._step:
            self._grid_origin_s, self._step = self.time_s, 0
        self.period_s = period_s

    def set_noise(self, noise_std_rad: float) -> None:
        """Measure with this standard deviation per tangential axis (rad) from now on."""
        if not (np.isfinite(noise_std_rad) and noise_std_rad >= 0):
            raise ValueError(f'noise_std_rad must be >= 0, got {noise_std_rad}')
        self.noise_std_rad = noise_std_rad

    @property
    def waiting(self) -> int:
        """Commands received and queued, not yet applied, refused or replaced."""
        return len(self._queued)

    # --- commands ----------------------------------------------------------------------
    def command_voltages(self, voltages_v: ArrayLike) -> str | None:
        """Queue voltages to hold from the next sample on.

        A hold replaces whatever the beams were given from then on, so it cuts a programme that
        is still running or queued (the device's drivers take the latest command).

        Returns
        -------
        str or None
            What the hold cut, if anything, to report.

        Raises
        ------
        CommandRejectedError
            For anything :func:`msg_defs.voltage_rules.check_voltages` refuses.
        """
        try:
            volts = check_voltages(voltages_v, self.voltage_limit_v)
        except VoltageRuleError as error:
            raise CommandRejectedError(str(error)) from None
        cut = self._cut_by_hold()
        # The hold overrides everything queued: programmes (reported) and earlier holds due at
        # the same sample (only the latest would count; a burst never fills the queue). None
        # of them reached the plant, so each is counted as dropped by replacement.
        self.counters.replaced += len(self._queued)
        self._queued.clear()
        self._queue(self.time_s, 'hold', volts, self.time_s)
        return cut

    def _cut_by_hold(self) -> str | None:
        """What a hold now overrides: the running programme and the queued ones (counted,
        reported as cut, and said, or None)."""
        queued = [item for item in self._queued if item.kind == 'programme']
        running = self._running is not None and self.time_s < self._running.end_s - TIME_TOL_S
        if not (queued or running):
            return None
        self.counters.cut += len(queued) + running
        what = []
        if running:
            assert self._running is not None  # for the type checker: ``running`` says so
            what.append(f'the programme running until t = {self._running.end_s:.4f} s')
            self._cut(self._running.asked_s, self._running.number, 'a voltage command')
        for item in queued:
            self._cut(item.asked_s, item.number, 'a voltage command before its start')
        if queued:
            what.append(f'{len(queued)} queued programme(s)')
        return (f'a voltage command at t = {self.time_s:.4f} s cut {" and ".join(what)}: the '
                'latest command holds the beams')

    def _cut(self, asked_s: float, number: int, by: str) -> None:
        if self._running is not None and self._running.number == number:
            self._running = None
        self._event(ProgrammeState.CUT, asked_s, number, f'cut by {by} at t = '
                    f'{self.time_s:.4f} s')

    def _event(self, state: ProgrammeState, asked_s: float, number: int, text: str) -> None:
        self._events.append(ProgrammeEvent(state, asked_s, number, self.time_s, text))

    def take_events(self) -> list[ProgrammeEvent]:
        """The programme events since the last call, oldest first (for the node to echo)."""
        events, self._events = self._events, []
        return events

    def command_programme(self, times_s: ArrayLike, voltages_v: Iterable[ArrayLike],
                          start_s: float = 0.0) -> None:
        """Queue a programme (segments relative to its start) starting at ``start_s``
        (simulated s; 0 or a past time: at the next sample).

        Raises
        ------
        CommandRejectedError
            For a programme that PulseProgramme refuses (see ``from_segments``).
        """
        self._received += 1
        try:
            programme = PulseProgramme.from_segments(times_s, voltages_v, self.voltage_limit_v)
            if start_s > self.time_s + MAX_START_AHEAD_S:
                raise CommandRejectedError(
                    f'starts at t = {start_s:.6g} s, {start_s - self.time_s:.6g} s after the '
                    f'simulated now (t = {self.time_s:.4f} s): stamps are simulated time '
                    '(/clock); stamp 0 starts a programme at once')
            if 0.0 < start_s < self.time_s - 1e-9:
                self.counters.late += 1  # started now instead
            self._queue(max(start_s, self.time_s), 'programme', programme, start_s,
                        self._received)
        except (ProgrammeError, CommandRejectedError) as error:
            self._event(ProgrammeState.REFUSED, start_s, self._received, str(error))
            raise CommandRejectedError(str(error)) from None

    def refuse_programme(self, asked_s: float, reason: str) -> None:
        """Book a programme refused before it reached the runner (a message that breaks the
        contract): numbered, and reported to its sender like any other refusal."""
        self._received += 1
        self._event(ProgrammeState.REFUSED, asked_s, self._received, reason)

    def _queue(self, start_s: float, kind: str, payload: NDArray[np.float64] | PulseProgramme,
               asked_s: float, number: int = 0) -> None:
        if len(self._queued) >= MAX_QUEUED_COMMANDS:
            raise CommandRejectedError(f'{MAX_QUEUED_COMMANDS} commands are already waiting '
                                       'for their start; this one is refused')
        self._queued.append(_Queued(start_s, kind, payload, asked_s, time.perf_counter(),
                                    number))
        self._queued.sort(key=lambda item: item.start_s)
        self._idle_published = False

    def _apply_due(self) -> list[str]:
        """Apply queued commands due now; returns the reasons of those the plant refused."""
        refused = []
        while self._queued and self._queued[0].start_s <= self.time_s + TIME_TOL_S:
            item = self._queued.pop(0)
            try:
                if item.kind == 'hold':
                    self.plant.hold(typing.cast(NDArray[np.float64], item.payload))
                else:
                    programme = typing.cast(PulseProgramme, item.payload)
                    before = self._check_start()
                    self.plant.run_programme(programme)
                    self._started(item)
                    if self.check is not None and before is not None:
                        self.check.started(self.time_s, *before, programme)
                self.counters.accepted += 1
            except (PlantError, ProgrammeError) as error:
                self.counters.rejected += 1
                refused.append(str(error))
                if item.kind == 'programme':
                    self._event(ProgrammeState.REFUSED, item.asked_s, item.number, str(error))
        return refused

    def _check_start(self) -> tuple[NDArray[np.float64] | None, NDArray[np.float64]] | None:
        """The plant's state and normal before a programme starts, for the check (if on)."""
        if self.check is None:
            return None
        return self.plant.model_state(), self.plant.snapshot().normal

    def _started(self, item: _Queued) -> None:
        """Book a programme the plant took: the one it replaced is cut; its start is reported
        and its end watched for."""
        if self._running is not None:
            self._cut(self._running.asked_s, self._running.number, 'a later programme')
        end_s = self.time_s + typing.cast(PulseProgramme, item.payload).duration_s
        self._running = _Running(item.asked_s, item.number, end_s)
        self.counters.programmes += 1
        self._acted.append(item.arrival_wall_s)
        self.timings.delays_sim_s.append(self.time_s - max(item.asked_s, 0.0))
        delay = (f', {self.time_s - item.asked_s:.4f} s after the start it asked for'
                 if item.asked_s > 0.0 and self.time_s > item.asked_s + TIME_TOL_S else '')
        self._event(ProgrammeState.STARTED, item.asked_s, item.number,
                    f'started at t = {self.time_s:.4f} s{delay}; its segments end at '
                    f't = {end_s:.4f} s')

    def _report_end(self) -> None:
        """Report the running programme's end once simulated time has reached it; the event
        carries the end itself, not the sample that shows it."""
        running = self._running
        if running is not None and self.time_s >= running.end_s - TIME_TOL_S:
            self._running = None
            self._events.append(ProgrammeEvent(ProgrammeState.ENDED, running.asked_s,
                                               running.number, running.end_s,
                                               f'ended at t = {running.end_s:.4f} s'))

    # --- time ----------------------------------------------------------------------------
    def idle(self) -> bool:
        """In lockstep: nothing in effect or queued, and the settled sample already out."""
        return (self.lockstep and not self._queued and self._idle_published
                and self.plant.time_s >= self.plant.busy_until_s - TIME_TOL_S)

    def tick(self) -> tuple[Sample | None, list[str]]:
        """Advance one period unless idle; returns (Sample or None, refused reasons).

        The first tick publishes the initial state without advancing.
        """
        refused = self._apply_due()
        if self.idle():
            return None, refused
        if self.counters.samples > 0:
            self._step += 1
            started = time.perf_counter()
            self.plant.advance(self.time_s)
            self.timings.integrating_s += time.perf_counter() - started
            refused += self._apply_due()
        self._report_end()
        snapshot = self.plant.snapshot()
        if self.check is not None:
            self.check.observe(snapshot.time_s, snapshot.normal)
        self.counters.samples += 1
        if (self.lockstep and self.plant.time_s >= self.plant.busy_until_s - TIME_TOL_S
                and not self._queued):
            self._idle_published = True
        acted, self._acted = tuple(self._acted), []
        return Sample(snapshot, self.measure(snapshot.normal), acted), refused

    def measure(self, normal: NDArray[np.float64]) -> NDArray[np.float64]:
        """The sensor's reading: the normal tilted by seeded Gaussian noise."""
        if self.noise_std_rad == 0.0:
            return np.array(normal, dtype=float)
        # Two orthonormal tangents of the normal carry the error; the result stays a unit vector.
        helper = np.array([1.0, 0.0, 0.0]) if abs(normal[0]) < 0.9 else np.array([0, 1.0, 0])
        t1 = np.cross(normal, helper)
        t1 /= np.linalg.norm(t1)
        t2 = np.cross(normal, t1)
        e1, e2 = self.rng.normal(0.0, self.noise_std_rad, 2)
        noisy = normal + e1 * t1 + e2 * t2
        return noisy / np.linalg.norm(noisy)
