"""The controller node's logic without ROS: wait for a kick to settle, then decide the next.

A :class:`KickCycle` takes measured samples of the surface normal and the reference as they
arrive, detects when the last kick has settled (its window is over and the normal has stopped
moving), lets the learning controller observe the kick, and asks it for the next command. It
holds, and says so, when no sample arrived for too long; it never kicks on a stale state.
"""

import dataclasses
import enum
import itertools
import math

import numpy as np

from sphere_control.geometry import error_angle_rad, error_direction_rad
from sphere_control.reachable import model_kicks, speed_ratios
from sphere_control.reference_motion import ReferenceMotion
from sphere_sim.model.rotations import angle_between

# Samples at or beyond the kick window with an angular speed below this count as settled. A
# landed sphere is held by its contacts' friction (docs/parameters.md), so only the kick's own
# ringing moves it: 0.2 deg/s is 0.004 deg between samples of a 50 Hz stream, the size of the
# settle band of the kick designs (0.005 deg).
DEFAULT_SETTLE_RATE_RAD_PER_S = math.radians(0.2)
DEFAULT_SETTLE_SAMPLES = 3
DEFAULT_STALE_TIMEOUT_S = 1.0
# A kick is scheduled this many sample periods after the sample it was decided on: the time
# the command has to reach a paced simulator (or the device) before it is due, so that it
# starts exactly when the cycle expects and the window it waits for is the kick's.
DEFAULT_LEAD_PERIODS = 2
# Lead before the sample period is known (one sample seen): two periods of a 50 Hz stream.
LEAD_BEFORE_PERIOD_KNOWN_S = 0.04


class Phase(enum.Enum):
    NO_STATE = 'no state'  # no sample yet (a reference is there)
    NO_REFERENCE = 'no reference'
    STALE = 'stale'  # no sample for stale_timeout_s of wall time: holding
    SETTLING = 'settling'  # a kick is in effect
    RESTING = 'resting'  # Phi below Phi_min
    KICKING = 'kicking'  # a command was just issued


@dataclasses.dataclass(frozen=True)
class Decision:
    """What the node does after a sample: a command (or None) and why.

    ``start_s`` is when the kick should start (simulated s): a few sample periods ahead, so
    that the command is there before it is due and the window the cycle waits for is the
    window the kick has.
    """

    phase: Phase
    command: object = None
    phi_rad: float = math.nan
    theta_rad: float = math.nan
    start_s: float = math.nan


class KickCycle:
    """Sequencing of kicks for a :class:`~sphere_control.command.Controller`.

    Parameters
    ----------
    controller : Controller
    window_s : float
        A kick's effect lasts this long after the sample it was decided on (simulated s).
    settle_samples : int
        Consecutive samples (after the window) that must show the normal at rest.
    settle_rate_rad_per_s : float
    stale_timeout_s : float
        Wall-clock time without a sample after which the state counts as stale.
    lead_periods : int
        Sample periods between the deciding sample and the kick's start.
    preview : bool
        Aim where the reference will be one window after its newest sample, estimated from
        its recent samples (:class:`ReferenceMotion`; a jump is not extrapolated), instead of
        at its newest sample.
    """

    def __init__(self, controller, window_s, settle_samples=DEFAULT_SETTLE_SAMPLES,
                 settle_rate_rad_per_s=DEFAULT_SETTLE_RATE_RAD_PER_S,
                 stale_timeout_s=DEFAULT_STALE_TIMEOUT_S, lead_periods=DEFAULT_LEAD_PERIODS,
                 preview=False):
        self.controller = controller
        self.window_s = window_s
        self.settle_samples = settle_samples
        self.settle_rate_rad_per_s = settle_rate_rad_per_s
        self.stale_timeout_s = stale_timeout_s
        self.lead_periods = lead_periods
        self.samples = []  # (time_s, normal), the last few
        self.reference = None
        self.last_sample_wall_s = None
        self.pending = None  # (start_s, normal_before, command)
        self.kicks = 0
        self.period_s = None  # the sample period, learnt from the stamps
        self.preview = preview
        self.reference_motion = ReferenceMotion()

    def on_reference(self, normal, time_s=None):
        """A reference sample; its stamp ``time_s`` (s) feeds the motion estimate."""
        self.reference = np.asarray(normal, dtype=float)
        if time_s is not None:
            self.reference_motion.add(time_s, self.reference)

    def target(self):
        """What the controller aims at: the reference, or with preview where it will be."""
        if self.preview:
            ahead = self.reference_motion.ahead(self.window_s)
            if ahead is not None:
                return ahead
        return self.reference

    def speed_ratio(self):
        """The reference's step per window over the furthest the controller's model of the
        kicks reaches along it (:mod:`sphere_control.reachable`); above 1 the reference
        outruns the plant. 0 for a reference standing still."""
        step = self.reference_motion.velocity_xy() * self.window_s
        return float(speed_ratios([step], lambda _: model_kicks(self.controller))[0])

    def on_sample(self, time_s, normal, wall_s):
        """Record a measured sample; returns the :class:`Decision` it leads to."""
        if self.samples and time_s > self.samples[-1][0]:
            gap = float(time_s) - self.samples[-1][0]
            self.period_s = gap if self.period_s is None else min(self.period_s, gap)
        self.samples.append((float(time_s), np.asarray(normal, dtype=float)))
        del self.samples[:-max(self.settle_samples, 2)]
        self.last_sample_wall_s = wall_s
        return self.decide()

    def check_stale(self, wall_s):
        """Decision when no sample came (call from a wall-clock timer)."""
        if self.last_sample_wall_s is None:
            return Decision(Phase.NO_STATE if self.reference is not None else
                            Phase.NO_REFERENCE)
        if wall_s - self.last_sample_wall_s > self.stale_timeout_s:
            return Decision(Phase.STALE)
        return None

    def settled(self):
        if self.pending is None:
            return True
        latest_s = self.samples[-1][0]
        if latest_s < self.pending[0] + self.window_s - 1e-9:
            return False
        recent = self.samples[-self.settle_samples:]
        if len(recent) < self.settle_samples:
            return False
        for (t0, n0), (t1, n1) in itertools.pairwise(recent):
            moved = angle_between(n0, n1)
            if t1 <= t0:
                if moved > 0.0:
                    return False  # a repeat of a sample must be the same sample
            elif moved / (t1 - t0) > self.settle_rate_rad_per_s:
                return False
        return True

    def decide(self):
        if not self.samples:
            return Decision(Phase.NO_STATE)
        if not self.settled():
            return Decision(Phase.SETTLING)
        time_s, normal = self.samples[-1]
        if self.pending is not None:
            _, before, command = self.pending
            self.controller.observe(before, command, normal)
            self.pending = None
        if self.reference is None:
            return Decision(Phase.NO_REFERENCE)
        phi = error_angle_rad(normal, self.reference)
        theta = error_direction_rad(normal, self.reference) if phi > 0.0 else 0.0
        command = self.controller.decide(normal, self.target())
        if command is None:
            return Decision(Phase.RESTING, None, phi, theta)
        lead_s = (LEAD_BEFORE_PERIOD_KNOWN_S if self.period_s is None
                  else self.lead_periods * self.period_s)
        start_s = time_s + lead_s
        self.pending = (start_s, normal, command)
        self.kicks += 1
        return Decision(Phase.KICKING, command, phi, theta, start_s)
