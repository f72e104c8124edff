"""The kick cycle without ROS: decide a kick, wait until the plant says it ran and its settle
period is over, learn from it, decide the next.

The controller node and the offline closed loop (:mod:`sphere_control.closed_loop`) both run
their kicks through a :class:`KickCycle`, so they cannot drift apart. A cycle takes measured
samples of the surface normal and the reference as they arrive, and the plant's reports on
each programme (:class:`~msg_defs.programme_events.ProgrammeEvent`: started, ended, cut,
refused). A kick is over on the first sample at or after its *reported* start plus the kick
period, once its end has been reported; the decision is made on that sample, and the
controller learns only from kicks that ran to their end. The start the cycle asked for never
times anything: a late command starts late, and the report says when.

It holds, and says so, when no sample arrived for too long; it never kicks on a stale state. A
programme that no report acknowledges within the stale timeout (lost on its way, or sent to a
plant that does not echo) is given up, not learned from, and the next kick decided.
"""

from __future__ import annotations

import dataclasses
import enum
import math
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

from msg_defs.device import NS_PER_S
from msg_defs.programme_events import ProgrammeState
from sphere_control.geometry import error_angle_rad, error_direction_rad
from sphere_control.reachable import model_kicks, speed_ratios
from sphere_control.reference_motion import ReferenceMotion

if TYPE_CHECKING:
    from msg_defs.programme_events import ProgrammeEvent
    from sphere_control.command import Command, Controller

DEFAULT_STALE_TIMEOUT_S = 1.0
# A kick is scheduled this many sample periods after the sample it was decided on: the time
# the command has to reach the plant before it is due, so that it starts where the cycle asked
# and the cycle is the kick period plus one sample.
DEFAULT_LEAD_PERIODS = 1
# Lead before the sample period is known (one sample seen): a period of a 100 Hz stream.
LEAD_BEFORE_PERIOD_KNOWN_S = 0.01
# Stamps travel in whole nanoseconds; a report names its programme by the stamp it was sent with.
STAMP_TOL_S = 0.5 / NS_PER_S


class Phase(enum.Enum):
    NO_STATE = 'no state'  # no sample yet (a reference is there)
    NO_REFERENCE = 'no reference'
    STALE = 'stale'  # no sample for stale_timeout_s of wall time: holding
    WAITING = 'waiting for the start'  # a kick was sent; the plant has not said it started
    SETTLING = 'settling'  # a kick is in effect
    RESTING = 'resting'  # Phi below Phi_min
    KICKING = 'kicking'  # a command was just issued


@dataclasses.dataclass(frozen=True)
class Decision:
    """What the node does after a sample or a report: a command (or None) and why.

    ``start_s`` is when the kick should start (simulated s): a sample period ahead, so that
    the command is there before it is due.
    """

    phase: Phase
    command: Command | None = None
    phi_rad: float = math.nan
    theta_rad: float = math.nan
    start_s: float = math.nan


@dataclasses.dataclass
class PendingKick:
    """A kick sent and not yet learned from: what it was decided on, and what the plant said.

    ``start_s`` and ``end_s`` stay NaN until the plant reports them; ``learn`` turns False
    when the kick was cut, whose outcome is not the kick's.
    """

    asked_s: float
    normal_before: NDArray[np.float64]
    command: Command
    sent_wall_s: float
    start_s: float = math.nan
    end_s: float = math.nan
    learn: bool = True


@dataclasses.dataclass
class CycleCounts:
    """The kicks of a cycle by what became of them. Every kick sent is landed, cut, refused,
    unanswered or, at most one at a time, still in flight (:meth:`KickCycle.in_flight`)."""

    kicks: int = 0  # sent
    landed: int = 0  # ran to their end and were learned from
    cut: int = 0  # cut by a later command: waited for, not learned from
    refused: int = 0  # the plant refused them: nothing ran
    unanswered: int = 0  # no report within the stale timeout: given up


class KickCycle:
    """Sequencing of kicks for a :class:`~sphere_control.command.Controller`.

    Parameters
    ----------
    controller : Controller
    kick_period_s : float
        A kick is over this long after its reported start (simulated s): its settle time,
        rounded up (:func:`sphere_sim.kicks.discrete.kick_period_s`).
    stale_timeout_s : float
        Wall-clock time without a sample after which the state counts as stale, and without a
        report after which a sent kick is given up.
    lead_periods : int
        Sample periods between the deciding sample and the kick's start (0: at that sample,
        as the offline loop does).
    preview : bool
        Aim where the reference will be one kick period after its newest sample, estimated
        from its recent samples (:class:`ReferenceMotion`; a jump is not extrapolated),
        instead of at its newest sample.
    """

    def __init__(self, controller: Controller, kick_period_s: float,
                 stale_timeout_s: float = DEFAULT_STALE_TIMEOUT_S,
                 lead_periods: int = DEFAULT_LEAD_PERIODS, preview: bool = False) -> None:
        self.controller = controller
        self.kick_period_s = kick_period_s
        self.stale_timeout_s = stale_timeout_s
        self.lead_periods = lead_periods
        self.preview = preview
        # (time_s, normal) of the newest sample
        self.latest: tuple[float, NDArray[np.float64]] | None = None
        self.reference: NDArray[np.float64] | None = None
        self.last_sample_wall_s: float | None = None
        self.pending: PendingKick | None = None
        self.counts = CycleCounts()
        self.period_s: float | None = None  # the sample period, learnt from the stamps
        self.reference_motion = ReferenceMotion()

    @property
    def kicks(self) -> int:
        return self.counts.kicks

    # --- inputs ------------------------------------------------------------------------
    def on_reference(self, normal: ArrayLike, time_s: float | None = None) -> None:
        """A reference sample; its stamp ``time_s`` (s) feeds the motion estimate."""
        self.reference = np.asarray(normal, dtype=float)
        if time_s is not None:
            self.reference_motion.add(time_s, self.reference)

    def record(self, time_s: float, normal: ArrayLike, wall_s: float | None = None) -> None:
        """Keep a measured sample as the newest (without deciding)."""
        if self.latest is not None and time_s > self.latest[0]:
            gap = float(time_s) - self.latest[0]
            self.period_s = gap if self.period_s is None else min(self.period_s, gap)
        self.latest = (float(time_s), np.asarray(normal, dtype=float))
        if wall_s is not None:
            self.last_sample_wall_s = wall_s

    def on_sample(self, time_s: float, normal: ArrayLike, wall_s: float) -> Decision:
        """Record a measured sample; returns the :class:`Decision` it leads to."""
        self.record(time_s, normal, wall_s)
        self._give_up_unanswered(wall_s)
        return self.decide(wall_s)

    def on_programme_event(self, event: ProgrammeEvent) -> Decision | None:
        """A plant's report on a programme (:class:`ProgrammeEvent`).

        Returns the :class:`Decision` it leads to when it ends the pending kick on a sample
        already seen, else None. Reports on other programmes (another sender's) are ignored.
        """
        if not self.concerns(event):
            return None
        p = self.pending
        assert p is not None  # the report concerns it
        if event.state is ProgrammeState.STARTED:
            p.start_s = event.time_s
        elif event.state is ProgrammeState.ENDED:
            p.end_s = event.time_s
        elif event.state is ProgrammeState.CUT:
            # Whatever ran of it is in the plant: wait a kick period from its start (or from
            # the cut, if it never started), but learn nothing from it.
            if math.isnan(p.start_s):
                p.start_s = event.time_s
            p.end_s, p.learn = event.time_s, False
            self.counts.cut += 1
        elif event.state is ProgrammeState.REFUSED:
            # Nothing ran. The next kick waits for the next sample: deciding at once would
            # answer a plant that refuses every kick with a flood of them.
            self.pending = None
            self.counts.refused += 1
            return None
        return self.decide() if self.over() and self.latest is not None else None

    def concerns(self, event: ProgrammeEvent) -> bool:
        """Whether a programme report is about the pending kick (named by its stamp)."""
        return (self.pending is not None
                and abs(event.asked_s - self.pending.asked_s) <= STAMP_TOL_S)

    def kick_ran(self, start_s: float, end_s: float) -> None:
        """Report that the pending kick started at ``start_s`` and ended at ``end_s`` (the
        offline loop's plant, which applies a kick at once)."""
        p = self.pending
        assert p is not None, 'no kick is pending'
        p.start_s, p.end_s = start_s, end_s

    def check_stale(self, wall_s: float) -> Decision | None:
        """Decision when no sample came (call from a wall-clock timer), or None. Never a kick:
        only a sample decides one (a lockstep plant repeats its last sample while it waits
        for a command, and the repeat gives up an unanswered kick)."""
        if self.last_sample_wall_s is None:
            return Decision(Phase.NO_STATE if self.reference is not None else
                            Phase.NO_REFERENCE)
        if wall_s - self.last_sample_wall_s > self.stale_timeout_s:
            self._give_up_unanswered(wall_s)
            return Decision(Phase.STALE)
        return None

    def in_flight(self) -> tuple[int, int]:
        """The kick sent and not yet counted as landed, cut, refused or unanswered, as (its
        start not yet reported, started and not yet landed): (0, 0), (1, 0) or (0, 1). With it
        the counts add up to the kicks sent. A plant counts a programme when it starts it, so
        at a stop its count may include the one whose start report had not yet arrived."""
        p = self.pending
        if p is None or not p.learn:  # a cut one is counted as cut
            return 0, 0
        return (1, 0) if math.isnan(p.start_s) else (0, 1)

    # --- the cycle ---------------------------------------------------------------------
    def over(self) -> bool:
        """True when no kick is in effect: none pending, or the pending one has reported its
        end and the newest sample is at least a kick period after its reported start."""
        p = self.pending
        if p is None:
            return True
        if math.isnan(p.start_s) or math.isnan(p.end_s) or self.latest is None:
            return False
        return self.latest[0] >= max(p.start_s + self.kick_period_s, p.end_s) - 1e-9

    def land(self) -> bool:
        """If the pending kick is over, let the controller learn from it (the newest sample
        is its outcome) and free the cycle; returns whether the cycle is free."""
        if not self.over():
            return False
        p = self.pending
        if p is not None:
            assert self.latest is not None  # over() saw it
            if p.learn:
                self.controller.observe(p.normal_before, p.command, self.latest[1])
                self.counts.landed += 1
            self.pending = None
        return True

    def decide(self, wall_s: float | None = None) -> Decision:
        """The next step on the newest sample: wait, rest or kick (``wall_s``: now, when the
        kick is sent; the newest sample's arrival by default)."""
        if self.latest is None:
            return Decision(Phase.NO_STATE)
        if not self.land():
            assert self.pending is not None  # land() frees the cycle when none is
            return Decision(Phase.WAITING if math.isnan(self.pending.start_s)
                            else Phase.SETTLING)
        time_s, normal = self.latest
        if self.reference is None:
            return Decision(Phase.NO_REFERENCE)
        phi = error_angle_rad(normal, self.reference)
        theta = error_direction_rad(normal, self.reference) if phi > 0.0 else 0.0
        lead_s = (LEAD_BEFORE_PERIOD_KNOWN_S if self.period_s is None
                  else self.period_s) * self.lead_periods
        start_s = round((time_s + lead_s) * NS_PER_S) / NS_PER_S
        aim = self.target(start_s + self.kick_period_s)
        assert aim is not None  # a reference has arrived
        command = self.controller.decide(normal, aim)
        if command is None:
            return Decision(Phase.RESTING, None, phi, theta)
        sent_wall_s = self.last_sample_wall_s if wall_s is None else wall_s
        self.pending = PendingKick(start_s, normal, command, sent_wall_s or 0.0)
        self.counts.kicks += 1
        return Decision(Phase.KICKING, command, phi, theta, start_s)

    def _give_up_unanswered(self, wall_s: float | None) -> bool:
        """Drop a pending kick no report has acknowledged for the stale timeout; True if so."""
        p = self.pending
        if (p is None or not math.isnan(p.start_s) or wall_s is None
                or wall_s - p.sent_wall_s <= self.stale_timeout_s):
            return False
        self.pending = None
        self.counts.unanswered += 1
        return True

    # --- aims --------------------------------------------------------------------------
    def target(self, landing_s: float) -> NDArray[np.float64] | None:
        """What the controller aims at: the reference, or with preview where it will be at
        ``landing_s`` (simulated s), when the kick about to be decided is over.

        The newest reference sample may be a reference period old (100 ms at the reference
        node's 10 Hz, more than two kick periods), so the preview runs from its stamp, not
        from the deciding sample. It is capped at a kick period and the motion estimate's
        history, so that a reference stamped on another clock is not carried far.
        """
        motion = self.reference_motion
        if self.preview and motion.times_s:
            horizon_s = min(max(landing_s - motion.times_s[-1], 0.0),
                            self.kick_period_s + motion.history_s)
            return motion.ahead(horizon_s)
        return self.reference

    def speed_ratio(self) -> float:
        """The reference's step per kick period over the furthest the controller's model of
        the kicks reaches along it (:mod:`sphere_control.reachable`); above 1 the reference
        outruns the plant. 0 for a reference standing still."""
        step = self.reference_motion.velocity_xy() * self.kick_period_s
        return float(speed_ratios([step], lambda _: model_kicks(self.controller))[0])
