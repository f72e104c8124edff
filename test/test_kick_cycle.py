"""The kick cycle without ROS: timed by the plant's reports, learning from landed kicks only,
staleness, and the same cycle in the offline loop."""

import math

import numpy as np
import pytest

from msg_defs.programme_events import ProgrammeEvent, ProgrammeState
from sphere_control.closed_loop import LoopSettings, run_closed_loop
from sphere_control.command import Command
from sphere_control.controllers import make_controller
from sphere_control.kick_cycle import KickCycle, Phase
from sphere_control.kick_plants import AnalyticKickPlant
from sphere_control.reference import Setpoint
from sphere_sim.kicks.discrete import DIAGONAL_DIRECTIONS_RAD, normal_from_xy

KICK_PERIOD_S = 0.05
PERIOD_S = 0.01
LEVEL = normal_from_xy(0.0, 0.0)
MOVED = normal_from_xy(0.0, 1e-3)


class ScriptedController:
    """Kicks action 1 at u_K 0.5 until told to rest; remembers what it observed."""

    def __init__(self):
        self.rest = False
        self.observed = []

    def decide(self, normal, reference):
        return None if self.rest else Command(1, 0.5)

    def observe(self, normal_before, command, normal_after):
        self.observed.append((normal_before, command, normal_after))


@pytest.fixture
def cycle():
    c = KickCycle(ScriptedController(), KICK_PERIOD_S, stale_timeout_s=1.0)
    c.on_reference(normal_from_xy(0.01, 0.02))
    return c


def report(state, asked_s, time_s, number=1):
    return ProgrammeEvent(state, asked_s, number, time_s)


def feed(cycle, times_s, normal, wall_s=0.0):
    return [cycle.on_sample(t, normal, wall_s) for t in times_s]


def test_the_kick_is_timed_from_its_reported_start_not_the_asked_one(cycle):
    cycle.controller.rest = True
    cycle.on_sample(0.0, LEVEL, wall_s=0.0)
    cycle.controller.rest = False
    first = cycle.on_sample(PERIOD_S, LEVEL, wall_s=0.0)  # the period is known: one ahead
    assert first.phase is Phase.KICKING and first.start_s == pytest.approx(2 * PERIOD_S)
    asked = first.start_s
    # The plant started it 30 ms late: no decision until 50 ms after that start.
    assert [d.phase for d in feed(cycle, (0.02, 0.03, 0.04), LEVEL)] == [Phase.WAITING] * 3
    assert cycle.on_programme_event(report(ProgrammeState.STARTED, asked, 0.05)) is None
    assert cycle.on_programme_event(report(ProgrammeState.ENDED, asked, 0.054)) is None
    phases = [d.phase for d in feed(cycle, (0.06, 0.07, 0.08, 0.09), LEVEL)]
    assert phases == [Phase.SETTLING] * 4
    decision = cycle.on_sample(0.10, MOVED, wall_s=0.0)
    assert decision.phase is Phase.KICKING  # on the sample that ends the period, no more
    assert decision.start_s == pytest.approx(0.11)
    before, command, after = cycle.controller.observed[0]
    np.testing.assert_array_equal(before, LEVEL)
    np.testing.assert_array_equal(after, MOVED)
    assert command == Command(1, 0.5) and cycle.counts.landed == 1 and cycle.kicks == 2


def _accounted(cycle):
    """The kicks sent, from the other counts and the one in flight."""
    c = cycle.counts
    return c.landed + c.cut + c.refused + c.unanswered + sum(cycle.in_flight())


def test_every_kick_sent_is_counted_once_the_one_in_flight_included(cycle):
    asked = cycle.on_sample(0.0, LEVEL, wall_s=0.0).start_s
    assert cycle.in_flight() == (1, 0) and _accounted(cycle) == cycle.kicks == 1
    cycle.on_programme_event(report(ProgrammeState.STARTED, asked, asked))
    assert cycle.in_flight() == (0, 1) and _accounted(cycle) == 1
    cycle.on_programme_event(report(ProgrammeState.ENDED, asked, asked + 0.004))
    assert cycle.in_flight() == (0, 1)  # over, but not yet landed: no sample since
    second = cycle.on_sample(asked + KICK_PERIOD_S, MOVED, wall_s=0.0)
    assert cycle.counts.landed == 1 and cycle.in_flight() == (1, 0)
    assert _accounted(cycle) == cycle.kicks == 2
    cycle.on_programme_event(report(ProgrammeState.STARTED, second.start_s, second.start_s, 2))
    cycle.on_programme_event(report(ProgrammeState.CUT, second.start_s, second.start_s, 2))
    assert cycle.counts.cut == 1 and cycle.in_flight() == (0, 0)  # counted as cut
    assert _accounted(cycle) == 2
    third = cycle.on_sample(second.start_s + KICK_PERIOD_S, MOVED, wall_s=0.0)
    cycle.on_programme_event(report(ProgrammeState.REFUSED, third.start_s, third.start_s, 3))
    assert cycle.counts.refused == 1 and _accounted(cycle) == cycle.kicks == 3
    cycle.on_sample(third.start_s + PERIOD_S, MOVED, wall_s=0.0)
    cycle.check_stale(wall_s=2.0)  # no report for the fourth: given up
    assert cycle.counts.unanswered == 1 and cycle.in_flight() == (0, 0)
    assert _accounted(cycle) == cycle.kicks == 4


def test_before_the_sample_period_is_known_the_lead_is_a_100_hz_period(cycle):
    assert cycle.on_sample(0.0, LEVEL, wall_s=0.0).start_s == pytest.approx(0.01)


def test_a_report_after_its_sample_decides_on_that_sample(cycle):
    """Reports and samples travel on different topics: either may arrive first."""
    asked = cycle.on_sample(0.0, LEVEL, wall_s=0.0).start_s
    cycle.on_programme_event(report(ProgrammeState.STARTED, asked, asked))
    feed(cycle, (0.01, 0.02, 0.03, 0.04, 0.05), LEVEL)
    assert cycle.on_sample(asked + KICK_PERIOD_S, MOVED, wall_s=0.0).phase is Phase.SETTLING
    decision = cycle.on_programme_event(report(ProgrammeState.ENDED, asked, asked + 0.004))
    assert decision is not None and decision.phase is Phase.KICKING
    np.testing.assert_array_equal(cycle.controller.observed[0][2], MOVED)


def test_reports_on_other_programmes_are_ignored(cycle):
    asked = cycle.on_sample(0.0, LEVEL, wall_s=0.0).start_s
    other = asked + 1e-6
    assert cycle.on_programme_event(report(ProgrammeState.STARTED, other, 0.0, 7)) is None
    assert cycle.on_programme_event(report(ProgrammeState.ENDED, other, 0.004, 7)) is None
    assert cycle.on_sample(0.2, MOVED, wall_s=0.0).phase is Phase.WAITING


def test_a_refused_kick_is_not_learned_from_and_the_next_waits_for_a_sample(cycle):
    asked = cycle.on_sample(0.0, LEVEL, wall_s=0.0).start_s
    cycle.on_sample(0.01, LEVEL, wall_s=0.0)
    # Not at once: a plant that refuses every kick would be flooded with them.
    assert cycle.on_programme_event(report(ProgrammeState.REFUSED, asked, 0.01)) is None
    assert cycle.on_sample(0.02, LEVEL, wall_s=0.0).phase is Phase.KICKING
    assert cycle.controller.observed == [] and cycle.counts.refused == 1


def test_a_cut_kick_is_waited_for_but_not_learned_from(cycle):
    asked = cycle.on_sample(0.0, LEVEL, wall_s=0.0).start_s
    cycle.on_programme_event(report(ProgrammeState.STARTED, asked, asked))
    cycle.on_programme_event(report(ProgrammeState.CUT, asked, asked + 0.002))
    assert cycle.on_sample(asked + 0.03, MOVED, wall_s=0.0).phase is Phase.SETTLING
    assert cycle.on_sample(asked + KICK_PERIOD_S, MOVED, wall_s=0.0).phase is Phase.KICKING
    assert cycle.controller.observed == [] and cycle.counts.cut == 1


def test_an_unanswered_kick_is_given_up_after_the_stale_timeout(cycle):
    cycle.on_sample(0.0, LEVEL, wall_s=10.0)
    assert cycle.on_sample(0.5, LEVEL, wall_s=10.9).phase is Phase.WAITING
    decision = cycle.on_sample(0.6, LEVEL, wall_s=11.1)  # 1.1 s of wall time, no report
    assert decision.phase is Phase.KICKING and cycle.counts.unanswered == 1
    assert cycle.controller.observed == []


def test_a_lockstep_repeat_after_a_lost_kick_gets_a_new_one(cycle):
    """A lockstep plant that never got the kick repeats its last sample while it waits."""
    cycle.on_sample(0.0, LEVEL, wall_s=0.0)
    assert cycle.check_stale(wall_s=0.9) is None
    decision = cycle.on_sample(0.0, LEVEL, wall_s=1.1)  # the repeat
    assert decision.phase is Phase.KICKING and cycle.counts.unanswered == 1
    assert cycle.pending.sent_wall_s == 1.1  # the new kick's own timeout starts now


def test_resting_reports_phi_and_theta(cycle):
    cycle.controller.rest = True
    decision = cycle.on_sample(0.0, LEVEL, wall_s=0.0)
    assert decision.phase is Phase.RESTING and decision.command is None
    assert decision.phi_rad == pytest.approx(math.asin(math.hypot(0.01, 0.02)), rel=1e-6)
    assert decision.theta_rad == pytest.approx(math.atan2(0.02, 0.01), abs=1e-6)


def test_stale_state_holds_and_says_so(cycle):
    assert cycle.check_stale(wall_s=5.0).phase is Phase.NO_STATE
    cycle.on_sample(0.0, LEVEL, wall_s=5.0)
    assert cycle.check_stale(wall_s=5.5) is None
    assert cycle.check_stale(wall_s=6.5).phase is Phase.STALE  # the pending kick is given up
    assert cycle.counts.unanswered == 1 and cycle.pending is None


def test_without_a_reference_nothing_is_sent():
    cycle = KickCycle(ScriptedController(), KICK_PERIOD_S)
    assert cycle.on_sample(0.0, LEVEL, wall_s=0.0).phase is Phase.NO_REFERENCE
    assert cycle.kicks == 0


class NodeLikeLoop:
    """The offline loop's plant, driven as the node drives the simulator: every decision on
    the sample a kick period after the reported start, the kick applied at its asked start."""

    def __init__(self, controller, plant, period_s, sample_period_s):
        self.cycle = KickCycle(controller, period_s, lead_periods=0)
        self.plant = plant
        self.sample_period_s = sample_period_s

    def run(self, normal, reference, duration_s):
        decisions = []
        self.cycle.on_reference(reference)
        for k in range(round(duration_s / self.sample_period_s) + 1):
            t = k * self.sample_period_s
            d = self.cycle.on_sample(t, normal, wall_s=0.0)
            if d.command is not None:
                normal = self.plant.kick(normal, d.command.action, d.command.intensity).normal
                self.cycle.on_programme_event(ProgrammeEvent(ProgrammeState.STARTED,
                                                             d.start_s, 1, d.start_s))
                self.cycle.on_programme_event(ProgrammeEvent(ProgrammeState.ENDED,
                                                             d.start_s, 1, d.start_s))
                decisions.append((t, d.command))
        return decisions


def test_the_offline_loop_and_a_sampled_cycle_take_the_same_kicks():
    """With samples between decisions, the node's cycle decides at the same times and takes
    the same kicks as the offline loop at the kick period."""
    plant = AnalyticKickPlant(math.radians(0.5), exponent=1.5)
    target = Setpoint((0.05, -0.03))

    def controller():
        return make_controller('extended', math.radians(0.05), math.radians(0.5),
                               DIAGONAL_DIRECTIONS_RAD)

    offline = run_closed_loop(controller(), plant, LEVEL, target,
                              LoopSettings(max_steps=30, kick_period_s=KICK_PERIOD_S))
    sampled = NodeLikeLoop(controller(), plant, KICK_PERIOD_S, PERIOD_S).run(
        LEVEL, normal_from_xy(*target.xy), 30 * KICK_PERIOD_S)
    kicked = [(t, a, u) for t, a, u in zip(offline.times_s[:-1], offline.actions,
                                           offline.intensities, strict=True) if a >= 0]
    assert len(kicked) >= 5
    assert [t for t, _ in sampled][:len(kicked)] == pytest.approx([t for t, _, _ in kicked])
    assert [c.action for _, c in sampled][:len(kicked)] == [a for _, a, _ in kicked]
    np.testing.assert_allclose([c.intensity for _, c in sampled][:len(kicked)],
                               [u for _, _, u in kicked], rtol=1e-12)
