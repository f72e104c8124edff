"""The controller node: kicks the sphere towards the reference, talking only over topics.

Subscribes to the measured ``/sphere/surface_normal``, ``/sphere/reference`` and the plant's
``/beams/programme_status``; when the plant has reported the last kick's start and end and a
kick period has passed since that start, it runs the basic or the extended controller (§4.2) on
that sample and publishes the chosen kick as a ``/beams/pulse_program`` — the same voltages a
real device's drivers take. When a rest begins it sends 0 V on ``/beams/voltage_command``
(with ``hold_each_sample``, for every sample: a lockstep simulator's time runs on those).
``/controller/status`` (5 Hz) says what it did and why: the newest decision (action, Phi,
Theta), learned directions and widths, the kicks sent, landed, cut, refused and unanswered,
and the samples decided on since the last status; when the state is stale it holds, sends
nothing, and says so.
"""

from __future__ import annotations

import math
import sys
import time
from typing import TYPE_CHECKING, Any

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.clock import Clock, ClockType
from rclpy.node import Node

from msg_defs.conversions import (
    ns_from_time,
    programme_events_from_msg,
    programme_to_msg,
    surface_normal_from_msg,
    time_from_ns,
    voltages_to_msg,
)
from msg_defs.device import BEAM_COUNT, NS_PER_S
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
from sphere_control.controllers import controller_for
from sphere_control.kick_cycle import KickCycle, Phase
from sphere_twin.node_runtime.pace import PaceMeter
from sphere_twin.node_runtime.parameter_specs import (
    accept_parameter_changes,
    declare_node_parameters,
)
from sphere_twin.node_runtime.ros_env import run_node
from sphere_twin.nodes.parameters import CONTROLLER_PARAMETERS

if TYPE_CHECKING:
    from sphere_control.kick_cycle import Decision

WARNING_PHASES = (Phase.STALE, Phase.NO_STATE, Phase.NO_REFERENCE)

STALE_CHECK_PERIOD_S = 0.25
# /controller/status goes out at this wall-clock period (5 Hz), not at the sample rate: each
# one carries the newest decision and the stamps of every sample decided on since the last.
STATUS_PERIOD_S = 0.2



class ControllerNode(Node):
    """Thin adapter of :class:`sphere_control.kick_cycle.KickCycle` onto the topics."""

    def __init__(self, **node_kwargs: Any) -> None:
        # Physics and tables load here rather than at import, so main() installs its signal
        # handlers first and a SIGINT during start-up is a clean shutdown.
        from sphere_control.intensity_calibration import calibrated
        from sphere_sim.kicks.discrete import kick_period_s
        from sphere_sim.kicks.lookup_table import load_kick_model

        super().__init__('controller', **node_kwargs)
        p = declare_node_parameters(self, CONTROLLER_PARAMETERS)
        accept_parameter_changes(self, CONTROLLER_PARAMETERS, self._parameter_changed)
        # The controller's intensities are calibrated on the tables' own level-state width
        # curves, as in the offline studies (sphere_control.intensity_calibration).
        table = calibrated(load_kick_model([t for t in p['tables'] if t]))
        self.kicks = table
        self.controller_kind = p['controller']
        self.kick_period_s = p['kick_period_s'] or kick_period_s(table)
        self.cycle = KickCycle(controller_for(p['controller'], table,
                                              math.radians(p['phi_min_deg'])),
                               self.kick_period_s, stale_timeout_s=p['stale_timeout_s'],
                               preview=p['preview'])
        self._outrun = False
        self._programme_pub = self.create_publisher(
            PULSE_PROGRAM.msg_type, PULSE_PROGRAM.name, PULSE_PROGRAM.qos.to_profile())
        self._voltage_pub = self.create_publisher(
            VOLTAGE_COMMAND.msg_type, VOLTAGE_COMMAND.name, VOLTAGE_COMMAND.qos.to_profile())
        self._status_pub = self.create_publisher(
            CONTROLLER_STATUS.msg_type, CONTROLLER_STATUS.name,
            CONTROLLER_STATUS.qos.to_profile())
        self.create_subscription(SURFACE_NORMAL.msg_type, SURFACE_NORMAL.name, self.on_normal,
                                 SURFACE_NORMAL.qos.to_profile())
        self.create_subscription(SPHERE_REFERENCE.msg_type, SPHERE_REFERENCE.name,
                                 self.on_reference, SPHERE_REFERENCE.qos.to_profile())
        self.create_subscription(PROGRAMME_STATUS.msg_type, PROGRAMME_STATUS.name,
                                 self.on_programme_status, PROGRAMME_STATUS.qos.to_profile())
        self.create_timer(STALE_CHECK_PERIOD_S, self.on_stale_check)
        # The status is the wall's, whatever clock the node runs on (a paced simulator's
        # /clock may crawl).
        self.create_timer(STATUS_PERIOD_S, self.on_status_timer,
                          clock=Clock(clock_type=ClockType.STEADY_TIME))
        self._last_phase: Phase | None = None
        self._latest: tuple[Decision, Any] | None = None  # (decision, stamp) for the status
        self._decided_s: list[float] = []  # samples decided on since the last status
        self._kicked_s: list[float] = []  # those of them that kicked
        self.hold_each_sample = p['hold_each_sample']
        self._hold_sent_at_s = -1.0
        self._hold_sent_wall_s = 0.0  # time.monotonic() when it went out
        self._resting = False  # a rest's 0 V command has gone out
        self.pace = PaceMeter()
        self.get_logger().info(f'{self.controller_kind} controller, Phi_min '
                               f'{p["phi_min_deg"]:g} deg, {len(table.directions_rad)} actions, '
                               f'kick period {self.kick_period_s * 1e3:.0f} ms, preview '
                               f'{"on" if p["preview"] else "off"}')

    def _parameter_changed(self, name: str, value: Any) -> None:
        """Take a ``ros2 param set`` of preview (the one settable parameter): the next kick
        aims with it."""
        self.cycle.preview = value
        self.get_logger().info(f'{name} set to {value}')

    def on_reference(self, msg: Any) -> None:
        try:
            self.cycle.on_reference(surface_normal_from_msg(msg),
                                    ns_from_time(msg.header.stamp) / NS_PER_S)
        except ValueError as error:
            self.get_logger().error(f'ignored {SPHERE_REFERENCE.name}: {error}')

    def on_normal(self, msg: Any) -> None:
        try:
            normal = surface_normal_from_msg(msg)
        except ValueError as error:
            self.get_logger().error(f'ignored {SURFACE_NORMAL.name}: {error}')
            return
        sample_s = ns_from_time(msg.header.stamp) / NS_PER_S
        self.pace.note(sample_s)
        self._act(self.cycle.on_sample(sample_s, normal, time.monotonic()))

    def on_programme_status(self, msg: Any) -> None:
        try:
            events = programme_events_from_msg(msg)
        except ValueError as error:
            self.get_logger().error(f'ignored {PROGRAMME_STATUS.name}: {error}')
            return
        for event in events:
            if self.cycle.concerns(event) and event.state in (ProgrammeState.REFUSED,
                                                              ProgrammeState.CUT):
                # The status topic carries no reason; the simulator's /diagnostics does.
                reason = event.text or f'the reason is on {DIAGNOSTICS.name}'
                self.get_logger().warning(f'our kick (programme {event.number}) '
                                          f'{event.state.value}: {reason}')
            decision = self.cycle.on_programme_event(event)
            if decision is not None:
                self._act(decision)

    def _act(self, decision: Decision) -> None:
        """Send what the decision asks for and say so; stamped with the deciding sample's
        (simulated) time."""
        sample_s = self.cycle.latest[0] if self.cycle.latest is not None else 0.0
        stamp = time_from_ns(round(sample_s * NS_PER_S))
        if decision.command is not None:
            assert self.cycle.latest is not None  # a kick is decided on a sample
            programme = self.kicks.programme(decision.command.action,
                                             decision.command.intensity, self.cycle.latest[1])
            start = time_from_ns(round(decision.start_s * NS_PER_S))
            self._programme_pub.publish(programme_to_msg(*programme.segments(), stamp=start))
        elif decision.phase is Phase.RESTING and self._hold_due(sample_s):
            self._hold_sent_at_s = sample_s
            self._hold_sent_wall_s = time.monotonic()
            self._voltage_pub.publish(voltages_to_msg([0.0] * BEAM_COUNT, stamp))
        self._note(decision, sample_s, stamp)

    def _hold_due(self, sample_s: float) -> bool:
        """Whether a resting decision on the sample at ``sample_s`` sends 0 V: once per rest,
        or (hold_each_sample) once per sample, one in flight at a time, since a lockstep
        simulator advances one sample per command and holds queued behind a later kick
        would delay it. A lockstep simulator that still repeats the sample held
        ``stale_timeout_s`` of wall time after the hold went out never took it (lost, or
        consumed without advancing): it is sent again, as an unanswered kick is given up
        and decided anew, or the run would wait forever."""
        if self.hold_each_sample:
            unanswered = (sample_s == self._hold_sent_at_s and time.monotonic()
                          - self._hold_sent_wall_s > self.cycle.stale_timeout_s)
            return sample_s > self._hold_sent_at_s or unanswered
        due, self._resting = not self._resting, True
        return due

    def _note(self, decision: Decision, sample_s: float, stamp: Any) -> None:
        """Keep what the next status says; a warning phase is logged when it begins."""
        phase = decision.phase
        if phase in WARNING_PHASES and phase != self._last_phase:
            self.get_logger().warning(f'holding: {phase.value}; sending nothing')
        self._last_phase = phase
        if phase is not Phase.RESTING:
            self._resting = False
        if phase in (Phase.RESTING, Phase.KICKING):
            self._decided_s.append(sample_s)
            if decision.command is not None:
                self._kicked_s.append(sample_s)
        self._latest = (decision, stamp)

    def on_status_timer(self) -> None:
        if self._latest is not None:
            self._publish_status(*self._latest)

    def on_stale_check(self) -> None:
        decision = self.cycle.check_stale(time.monotonic())
        if decision is not None:
            # Stamped with the newest sample's time (0 before one): the node's own clock
            # would be the wall's unless use_sim_time, and every stamp is simulated time.
            self._act(decision)

    def _publish_status(self, decision: Decision, stamp: Any) -> None:
        """The newest decision, the counts so far and the samples decided on since the last
        status (their stamps, simulated s: where the loop saw a settled state)."""
        phase = decision.phase
        level = DiagnosticStatus.WARN if phase in WARNING_PHASES else DiagnosticStatus.OK
        counts = self.cycle.counts
        values = [('phase', phase.value), ('kicks', counts.kicks), ('landed', counts.landed),
                  ('cut', counts.cut), ('refused', counts.refused),
                  ('unanswered', counts.unanswered),
                  ('phi_deg', f'{math.degrees(decision.phi_rad):.5f}'),
                  ('theta_deg', f'{math.degrees(decision.theta_rad):.3f}'),
                  ('reference_speed_ratio', f'{self._speed_check():.3f}'),
                  ('decided_s', ' '.join(f'{t:.6f}' for t in self._decided_s)),
                  ('kicked_s', ' '.join(f'{t:.6f}' for t in self._kicked_s))]
        self._decided_s, self._kicked_s = [], []
        if decision.command is not None:
            values += [('action', decision.command.action),
                       ('intensity', f'{decision.command.intensity:.4f}')]
        belief = self.cycle.controller.believed_kicks()
        if belief.learned:  # what it has learned so far; a fixed model is in its parameters
            values.append(('directions_deg', ' '.join(f'{math.degrees(d):.2f}'
                                                      for d in belief.directions_rad)))
            values.append(('full_widths_deg', ' '.join(f'{math.degrees(w):.5f}'
                                                       for w in belief.full_widths_rad)))
        message = (f'kick action {decision.command.action} at u_K '
                   f'{decision.command.intensity:.3f}' if decision.command is not None
                   else phase.value)
        status = DiagnosticStatus(level=level, name=f'controller: {self.controller_kind}',
                                  hardware_id='sphere_twin', message=message,
                                  values=[KeyValue(key=k, value=str(v)) for k, v in values])
        array = DiagnosticArray(status=[status])
        array.header.stamp = stamp
        self._status_pub.publish(array)

    def _speed_check(self) -> float:
        """The reference's step per kick period over the furthest the learned kicks reach
        along it; a line in the log whenever it crosses 1 (the reference outruns the plant)."""
        ratio = self.cycle.speed_ratio()
        if (ratio > 1.0) != self._outrun:
            self._outrun = ratio > 1.0
            if self._outrun:
                self.get_logger().warning(
                    f'the reference moves {ratio:.2f} times faster than the kicks can follow '
                    f'(at {self.kick_period_s * 1e3:.0f} ms per kick)')
            else:
                self.get_logger().info('the kicks can follow the reference again')
        return ratio

    def summary(self) -> str:
        """The final line: the kicks sent and what became of each, the one in flight at the
        stop included (the simulator counts the programmes it started), and the pace."""
        c = self.cycle.counts
        not_started, not_landed = self.cycle.in_flight()
        return (f'controller: {c.kicks} kicks sent over {self.pace.simulated_span_s():.3f} s of '
                f'samples ({c.landed} landed, {c.cut} cut, {c.refused} refused, '
                f'{c.unanswered} unanswered, {not_started} awaiting its start report, '
                f'{not_landed} started and not yet landed); real-time factor '
                f'{self.pace.real_time_factor():.3f}')


def main(args: list[str] | None = None) -> int:
    return run_node(ControllerNode, args, farewell=ControllerNode.summary, name='controller',
                    parameters=CONTROLLER_PARAMETERS)


if __name__ == '__main__':
    sys.exit(main())
