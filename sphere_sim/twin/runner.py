"""The simulator's clock and command handling, free of ROS.

:class:`TwinRunner` owns a plant, the simulated time grid, the queue of commands, the
measurement noise and the lockstep rule; the simulator node only converts messages and calls
it. Every command is checked here against the device's rules (:mod:`msg_defs.voltage_rules`),
where it enters the twin, and a rejected one leaves the plant untouched.
"""

import collections
import dataclasses
import time
import typing

import numpy as np

from msg_defs.device import VOLTAGE_LIMIT_V
from msg_defs.voltage_rules import VoltageRuleError, check_voltages
from sphere_sim.model.programme import ProgrammeError, PulseProgramme
from sphere_sim.twin.plants import TIME_TOL_S, PlantError

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
    payload: object
    asked_s: float
    arrival_wall_s: float


class CommandError(ValueError):
    """A command that breaks the contract or the plant's limits; nothing was changed."""


@dataclasses.dataclass(frozen=True)
class Sample:
    """One published instant: the true snapshot and the measured (noisy) normal."""

    snapshot: object
    measured_normal: np.ndarray


@dataclasses.dataclass
class TwinCounters:
    samples: int = 0
    accepted: int = 0
    rejected: int = 0
    programmes: int = 0
    late: int = 0  # programmes whose start time had passed when they arrived
    cut: int = 0  # programmes a later voltage command cut short or dropped


@dataclasses.dataclass
class TwinTimings:
    """Where a run's wall time went, and how long programmes took to act (s).

    ``integrating_s`` is the plant's own time (its ``advance``); the node adds what it spends
    publishing. A programme's latency is from its arrival (``command_programme``) to the end
    of the tick that first shows its effect, in wall time, and from the start it asked for to
    the start it got, in simulated time.
    """

    integrating_s: float = 0.0
    publishing_s: float = 0.0
    latencies_wall_s: collections.deque = dataclasses.field(
        default_factory=lambda: collections.deque(maxlen=LATENCY_HISTORY))
    delays_sim_s: collections.deque = dataclasses.field(
        default_factory=lambda: collections.deque(maxlen=LATENCY_HISTORY))

    def latency_summary(self):
        """(median, largest) wall latency in s; NaNs before the first programme."""
        if not self.latencies_wall_s:
            return float('nan'), float('nan')
        return float(np.median(self.latencies_wall_s)), float(max(self.latencies_wall_s))

    def delay_median_s(self):
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
    """

    def __init__(self, plant, period_s, noise_std_rad=0.0, seed=0, lockstep=False,
                 voltage_limit_v=VOLTAGE_LIMIT_V):
        if not (np.isfinite(period_s) and period_s > 0):
            raise ValueError(f'period_s must be a positive number, got {period_s}')
        if not (np.isfinite(noise_std_rad) and noise_std_rad >= 0):
            raise ValueError(f'noise_std_rad must be >= 0, got {noise_std_rad}')
        self.plant = plant
        self.period_s = period_s
        self.noise_std_rad = noise_std_rad
        self.rng = np.random.default_rng(seed)
        self.lockstep = lockstep
        self.voltage_limit_v = voltage_limit_v
        self.counters = TwinCounters()
        self.timings = TwinTimings()
        self._queued = []  # _Queued, in start order, applied at the sample boundary they are due
        self._acted = []  # (arrival_wall_s) of programmes applied in this tick
        self._programme_end_s = -1.0  # when the last programme applied switches off
        self._step = 0
        self._idle_published = False

    @property
    def time_s(self):
        return self._step * self.period_s

    # --- commands ----------------------------------------------------------------------
    def command_voltages(self, voltages_v):
        """Queue voltages to hold from the next sample on.

        A hold replaces whatever the beams were given from then on, so it cuts a programme that
        is still running or queued (the device's drivers take the latest command).

        Returns
        -------
        str or None
            What the hold cut, if anything, to report.

        Raises
        ------
        CommandError
            For anything :func:`msg_defs.voltage_rules.check_voltages` refuses.
        """
        try:
            volts = check_voltages(voltages_v, self.voltage_limit_v)
        except VoltageRuleError as error:
            raise CommandError(str(error)) from None
        cut = self._cut_by_hold()
        # The hold overrides everything queued: programmes (reported) and earlier holds due at
        # the same sample (only the latest would count; a burst never fills the queue).
        self._queued.clear()
        self._queue(self.time_s, 'hold', volts, self.time_s)
        return cut

    def _cut_by_hold(self):
        """What a hold now overrides: the running programme and the queued ones (counted and
        said, or None)."""
        queued = [item for item in self._queued if item.kind == 'programme']
        running = self.time_s < self._programme_end_s - TIME_TOL_S
        if not (queued or running):
            return None
        self.counters.cut += len(queued) + running
        what = []
        if running:
            what.append(f'the programme running until t = {self._programme_end_s:.4f} s')
            self._programme_end_s = self.time_s
        if queued:
            what.append(f'{len(queued)} queued programme(s)')
        return (f'a voltage command at t = {self.time_s:.4f} s cut {" and ".join(what)}: the '
                'latest command holds the beams')

    def command_programme(self, times_s, voltages_v, start_s=0.0):
        """Queue a programme (segments relative to its start) starting at ``start_s``
        (simulated s; 0 or a past time: at the next sample).

        Raises
        ------
        CommandError
            For a programme that PulseProgramme refuses (see ``from_segments``).
        """
        try:
            programme = PulseProgramme.from_segments(times_s, voltages_v, self.voltage_limit_v)
        except ProgrammeError as error:
            raise CommandError(str(error)) from None
        if start_s > self.time_s + MAX_START_AHEAD_S:
            raise CommandError(
                f'starts at t = {start_s:.6g} s, {start_s - self.time_s:.6g} s after the '
                f'simulated now (t = {self.time_s:.4f} s): stamps are simulated time (/clock); '
                'stamp 0 starts a programme at once')
        if 0.0 < start_s < self.time_s - 1e-9:
            self.counters.late += 1  # started now instead
        self._queue(max(start_s, self.time_s), 'programme', programme, start_s)

    def _queue(self, start_s, kind, payload, asked_s):
        if len(self._queued) >= MAX_QUEUED_COMMANDS:
            raise CommandError(f'{MAX_QUEUED_COMMANDS} commands are already waiting for their '
                               'start; this one is refused')
        self._queued.append(_Queued(start_s, kind, payload, asked_s, time.perf_counter()))
        self._queued.sort(key=lambda item: item.start_s)
        self._idle_published = False

    def _apply_due(self):
        """Apply queued commands due now; returns the reasons of those the plant refused."""
        refused = []
        while self._queued and self._queued[0].start_s <= self.time_s + TIME_TOL_S:
            _, kind, payload, asked_s, arrival_wall_s = self._queued.pop(0)
            try:
                if kind == 'hold':
                    self.plant.hold(payload)
                else:
                    self.plant.run_programme(payload)
                    self._programme_end_s = self.time_s + payload.duration_s
                    self.counters.programmes += 1
                    self._acted.append(arrival_wall_s)
                    self.timings.delays_sim_s.append(self.time_s - max(asked_s, 0.0))
                self.counters.accepted += 1
            except (PlantError, ProgrammeError) as error:
                self.counters.rejected += 1
                refused.append(str(error))
        return refused

    # --- time ----------------------------------------------------------------------------
    def idle(self):
        """In lockstep: nothing in effect or queued, and the settled sample already out."""
        return (self.lockstep and not self._queued and self._idle_published
                and self.plant.time_s >= self.plant.busy_until_s - TIME_TOL_S)

    def tick(self):
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
        snapshot = self.plant.snapshot()
        self.counters.samples += 1
        if (self.lockstep and self.plant.time_s >= self.plant.busy_until_s - TIME_TOL_S
                and not self._queued):
            self._idle_published = True
        return Sample(snapshot, self.measure(snapshot.normal)), refused

    def sample_out(self):
        """Call once the tick's sample is published: the programmes applied in that tick have
        now shown their effect, and their wall latency is recorded."""
        now = time.perf_counter()
        self.timings.latencies_wall_s.extend(now - arrival for arrival in self._acted)
        self._acted.clear()

    def measure(self, normal):
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
