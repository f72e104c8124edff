"""The controller node's sequencing without ROS: settle detection, staleness, learning hook."""

import math

import numpy as np
import pytest

from sphere_control.command import Command
from sphere_control.kick_cycle import KickCycle, Phase
from sphere_sim.kicks.discrete import normal_from_xy

WINDOW_S = 0.06
PERIOD_S = 0.02


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
    c = KickCycle(ScriptedController(), WINDOW_S, settle_samples=3,
                  settle_rate_rad_per_s=math.radians(2.0), stale_timeout_s=1.0)
    c.on_reference(normal_from_xy(0.01, 0.02))
    return c


def test_no_kick_before_the_window_is_over_and_the_normal_stops(cycle):
    start = normal_from_xy(0.0, 0.0)
    first = cycle.on_sample(0.0, start, wall_s=0.0)
    assert first.phase is Phase.KICKING
    assert first.start_s == pytest.approx(0.04)  # two periods ahead, before the period is known
    moved = normal_from_xy(0.0, 1e-3)
    phases = [cycle.on_sample(k * PERIOD_S, moved if k >= 5 else start, wall_s=0.0).phase
              for k in range(1, 9)]
    # The kick runs from 0.04 s to 0.10 s. At 0.10 and 0.12 s the last three samples still
    # contain the jump (1 mrad in 20 ms = 2.9 deg/s); at 0.14 s they are at rest: kick again.
    assert phases == [Phase.SETTLING] * 6 + [Phase.KICKING, Phase.SETTLING]
    assert cycle.pending[0] == pytest.approx(0.14 + 2 * PERIOD_S)  # the period is known now
    before, command, after = cycle.controller.observed[0]
    np.testing.assert_array_equal(before, start)
    np.testing.assert_array_equal(after, moved)
    assert command == Command(1, 0.5) and cycle.kicks == 2


def test_repeats_of_the_settled_sample_count_as_rest(cycle):
    """In lockstep the simulator repeats its last sample while idle."""
    cycle.on_sample(0.0, normal_from_xy(0.0, 0.0), wall_s=0.0)  # kick from 0.04 s to 0.10 s
    settled = normal_from_xy(0.0, 1e-3)
    phases = [cycle.on_sample(0.04 + WINDOW_S, settled, wall_s=0.0).phase for _ in range(3)]
    # Two samples are too few to judge; with the repeat the window is over and at rest. The
    # next repeat belongs to the new kick's window.
    assert phases == [Phase.SETTLING, Phase.KICKING, Phase.SETTLING]
    assert len(cycle.controller.observed) == 1


def test_resting_reports_phi_and_theta(cycle):
    cycle.controller.rest = True
    decision = cycle.on_sample(0.0, normal_from_xy(0.0, 0.0), wall_s=0.0)
    assert decision.phase is Phase.RESTING and decision.command is None
    assert decision.phi_rad == pytest.approx(math.asin(math.hypot(0.01, 0.02)), rel=1e-6)
    assert decision.theta_rad == pytest.approx(math.atan2(0.02, 0.01), abs=1e-6)


def test_stale_state_holds_and_says_so(cycle):
    assert cycle.check_stale(wall_s=5.0).phase is Phase.NO_STATE
    cycle.on_sample(0.0, normal_from_xy(0.0, 0.0), wall_s=5.0)
    assert cycle.check_stale(wall_s=5.5) is None
    assert cycle.check_stale(wall_s=6.5).phase is Phase.STALE


def test_without_a_reference_nothing_is_sent():
    cycle = KickCycle(ScriptedController(), WINDOW_S)
    assert cycle.on_sample(0.0, normal_from_xy(0.0, 0.0), wall_s=0.0).phase is \
        Phase.NO_REFERENCE
    assert cycle.kicks == 0
