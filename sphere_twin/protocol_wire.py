"""A device on the ROS topics as the experiment protocol's loop sees it
(:class:`sphere_twin.protocol_run.ProtocolDevice`): programmes out on ``/beams/pulse_program``,
stamped with their start on the device's clock (the stamps of its samples), and the measured
normals in from ``/sphere/surface_normal``.

A device whose time runs on its own (hardware, a paced or unpaced simulator) is sent each
programme :data:`START_LEAD_S` after its newest sample, so that it arrives before its start,
and its samples are taken as they come. A lockstep simulator advances only while a command is
in effect: once its programme is over it repeats its last sample (the same stamp) and waits;
the device then asks it for each further resting sample with a 0 V hold (one sample per hold),
as a controller does with ``hold_each_sample``. A hold is sent only once the last programme's
segments are over, so it never cuts one; hardware never repeats a stamp and is never sent one.
"""

from __future__ import annotations

import bisect
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np

from msg_defs.device import BEAM_IDS, NS_PER_S, SENSOR_RATE_HZ

if TYPE_CHECKING:
    from numpy.typing import NDArray

    from sphere_sim.model.programme import PulseProgramme
    from sphere_twin.testing import TopicProbe

# A programme starts this long after the newest sample: one the device takes within five
# sample periods starts on time (a controller allows one; a busy machine's DDS and a paced
# simulator's catch-up take more).
START_LEAD_S = 0.05
# Wall time for the first sample, and per simulated second of samples asked for, before the
# device counts as silent (a lockstep simulator integrating the continuous model takes a few
# ms per sample; hardware one sample period).
FIRST_SAMPLE_TIMEOUT_S = 60.0
WALL_PER_SIMULATED_S = 30.0
TIME_TOL_S = 1e-6
# A hold not answered by a sample within this wall time is sent again (one lost on the way
# would leave a lockstep simulator waiting for good).
HOLD_RETRY_S = 2.0


class DeviceError(RuntimeError):
    """The device refused a programme or fell silent."""


class StoppedError(Exception):
    """A stop signal came while the loop waited for the device."""


class TopicDevice:
    """The protocol's device over the topics, through ``probe`` (a
    :class:`sphere_twin.testing.TopicProbe` recording ``/sphere/surface_normal`` and
    ``/beams/programme_status``).

    ``stopped()`` is asked while waiting: True ends the wait with :class:`StoppedError`.
    """

    def __init__(self, probe: TopicProbe, stopped: Callable[[], bool] = lambda: False,
                 period_s: float = 1.0 / SENSOR_RATE_HZ,
                 start_lead_s: float = START_LEAD_S) -> None:
        self.probe = probe
        self.stopped = stopped
        self.period_s = period_s
        self.start_lead_s = start_lead_s
        self.stamps: list[float] = []  # distinct sample stamps, in order
        self.normals: list[NDArray[np.float64]] = []
        self.holds = 0
        self.programmes = 0
        self._after_s = -np.inf  # run() hands back samples stamped after this
        self._busy_until_s = -np.inf  # the last programme's segments end here
        self._repeated = False  # the newest sample came again: a lockstep simulator is idle
        self._hold_pending = False
        self._hold_sent_s = 0.0
        self._from_hold = False  # the newest sample answered a hold: idle again
        self._sent_stamps: set[int] = set()

    @property
    def samples(self) -> int:
        return len(self.stamps)

    # --- the loop's interface ------------------------------------------------------------
    def send(self, programme: PulseProgramme) -> None:
        from msg_defs.conversions import programme_to_msg, time_from_ns
        from msg_defs.topics import PULSE_PROGRAM

        self.wait_for_first_sample()
        start_ns = round((self.stamps[-1] + self.start_lead_s) * NS_PER_S)
        times, volts = programme.segments()
        self.probe.publisher(PULSE_PROGRAM).publish(
            programme_to_msg(times, volts, time_from_ns(start_ns)))
        self._sent_stamps.add(start_ns)
        self.programmes += 1
        start_s = start_ns / NS_PER_S
        self._busy_until_s = start_s + programme.duration_s
        self._after_s = start_s - TIME_TOL_S

    def run(self, duration_s: float) -> NDArray[np.float64]:
        wanted = max(1, round(duration_s / self.period_s))
        first = bisect.bisect_right(self.stamps, self._after_s)

        def enough() -> bool:
            self._take()
            return len(self.stamps) - first >= wanted

        def done() -> bool:
            if self.stopped():
                raise StoppedError
            if enough():
                return True
            self._advance_if_idle()
            return False

        self.wait_for_first_sample()
        self.probe.spin_until(done, FIRST_SAMPLE_TIMEOUT_S + WALL_PER_SIMULATED_S * duration_s,
                              f'{wanted} samples on the device\'s normal topic')
        self._after_s = self.stamps[first + wanted - 1]
        return np.array(self.normals[first:first + wanted])

    # --- samples ---------------------------------------------------------------------------
    def wait_for_first_sample(self) -> None:
        def done() -> bool:
            if self.stopped():
                raise StoppedError
            self._take()
            return bool(self.stamps)

        if not self.stamps:
            self.probe.spin_until(done, FIRST_SAMPLE_TIMEOUT_S,
                                  'sample from the device (is it running on this domain?)')

    def _take(self) -> None:
        """File the samples and programme reports that came in."""
        from msg_defs.conversions import ns_from_time, surface_normal_from_msg
        from msg_defs.topics import PROGRAMME_STATUS, SURFACE_NORMAL

        messages = self.probe.messages[SURFACE_NORMAL.name]
        taken, messages[:] = list(messages), []
        for msg in taken:
            t = ns_from_time(msg.header.stamp) / NS_PER_S
            if self.stamps and t <= self.stamps[-1] + TIME_TOL_S:
                self._repeated |= abs(t - self.stamps[-1]) <= TIME_TOL_S
                continue
            self.stamps.append(t)
            self.normals.append(surface_normal_from_msg(msg))
            self._repeated = False
            self._from_hold, self._hold_pending = self._hold_pending, False
        reports = self.probe.messages.get(PROGRAMME_STATUS.name)
        if reports:
            taken, reports[:] = list(reports), []
            self._check_reports(taken)

    def _check_reports(self, messages: list[Any]) -> None:
        """A programme of ours the device refused ends the run (its samples would never
        come)."""
        from msg_defs.conversions import programme_events_from_msg
        from msg_defs.programme_events import ProgrammeState

        for msg in messages:
            for event in programme_events_from_msg(msg):
                if (event.state is ProgrammeState.REFUSED
                        and round(event.asked_s * NS_PER_S) in self._sent_stamps):
                    raise DeviceError(f'the device refused the programme for t = '
                                      f'{event.asked_s:.4f} s'
                                      + (f': {event.text}' if event.text else ''))

    def _advance_if_idle(self) -> None:
        """Ask an idle lockstep simulator for one more sample: a 0 V hold, once the last
        programme is over and the simulator has shown it waits (it repeated its newest
        sample, or that sample answered a hold)."""
        from msg_defs.conversions import voltages_to_msg
        from msg_defs.topics import VOLTAGE_COMMAND

        if self._hold_pending and time.monotonic() - self._hold_sent_s > HOLD_RETRY_S:
            self._hold_pending, self._from_hold = False, True
        if (self._hold_pending or not self.stamps
                or self.stamps[-1] < self._busy_until_s - TIME_TOL_S
                or not (self._repeated or self._from_hold)):
            return
        self.probe.publisher(VOLTAGE_COMMAND).publish(voltages_to_msg([0.0] * len(BEAM_IDS)))
        self.holds += 1
        self._hold_pending, self._repeated, self._from_hold = True, False, False
        self._hold_sent_s = time.monotonic()
