"""The simulator node: the twin behind the device's topics.

Takes ``/beams/voltage_command`` and ``/beams/pulse_program``, runs the continuous or the
discrete plant, and publishes ``/sphere/surface_normal`` (what the device's sensor measures,
with optional seeded noise), ``/sphere/state``, ``/beams/state`` and ``/beams/voltage`` (the
truth), markers, ``/clock``, ``/diagnostics`` and ``/beams/programme_status`` (each
programme's actual start and end, or its cut or refusal). A command that breaks the contract is
rejected with a logged error and a diagnostics entry; it never reaches the plant.
"""

from __future__ import annotations

import os
import sys
import time
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.event_handler import (
    PublisherEventCallbacks,
    QoSMessageLostInfo,
    QoSPublisherMatchedInfo,
    SubscriptionEventCallbacks,
)
from rclpy.node import Node
from rosgraph_msgs.msg import Clock

from msg_defs.conversions import (
    beam_state_to_msg,
    ns_from_time,
    programme_event_to_msg,
    programme_from_msg,
    sphere_state_to_msg,
    surface_normal_to_msg,
    time_from_ns,
    voltages_from_msg,
    voltages_to_msg,
)
from msg_defs.device import NS_PER_S
from msg_defs.markers import twin_markers
from msg_defs.topics import (
    BEAM_STATE,
    BEAM_VOLTAGE,
    CLOCK,
    DIAGNOSTICS,
    MARKERS,
    PROGRAMME_STATUS,
    PULSE_PROGRAM,
    SPHERE_STATE,
    SURFACE_NORMAL,
    VOLTAGE_COMMAND,
)
from msg_defs.transforms import (
    NO_TF_LINE,
    TF_QUEUE_DEPTH,
    TF_TOPIC,
    sphere_transform_msg,
    tf_message_type,
)
from sphere_sim.twin.report_limit import CountedWarning, ReportLimit
from sphere_twin.node_runtime.outbox import Outbox
from sphere_twin.node_runtime.parameter_specs import (
    StartupError,
    accept_parameter_changes,
    declare_node_parameters,
)
from sphere_twin.node_runtime.ros_env import DISCOVERY_RANGE_VAR, run_node
from sphere_twin.nodes.parameters import SIMULATOR_PARAMETERS

if TYPE_CHECKING:
    from msg_defs.programme_events import ProgrammeEvent
    from sphere_sim.twin.plants import TwinPlant
    from sphere_sim.twin.runner import Sample

# The physics (scipy, numba, the kick table) is imported when the node is built, not with this
# module, so that main() installs its signal handlers first: a SIGINT during the seconds of
# start-up is then a clean shutdown like any other.

MARKER_EVERY_N_SAMPLES = 5
# As-fast-as-possible and lockstep runs still yield to the executor between samples, so
# commands are taken in between.
FAST_TIMER_PERIOD_S = 1e-4
# While idle in lockstep, the last sample is repeated at this wall-clock period so that a
# subscriber that joined late still receives the state.
IDLE_REPEAT_PERIOD_S = 0.2
# A paced run is anchored to the wall clock: its timer fires this many times per sample and
# ticks whenever simulated time is behind, so a sample that cost more than its period (the
# first milliseconds of a kick) is caught up at this multiple of the pace. Not faster: a
# controller schedules a kick a sample period ahead of the sample it decided on, and a burst
# of samples would pass that start before the command arrives.
CATCH_UP_SPEEDUP = 2
# The status on /diagnostics is published at this wall-clock period, so that a healthy twin
# is visible to `ros2 topic echo /diagnostics` and to a supervisor.
STATUS_PERIOD_S = 1.0
# Why the simulator never takes use_sim_time, at start-up or from `ros2 param set`: its node
# clock would wait for the /clock that only its own sampling publishes.
IS_THE_CLOCK = ('is the clock (it publishes /clock): run it without use_sim_time; the other '
                'nodes take use_sim_time:=true')


def _clock_follower(use_sim_time: bool) -> str | None:
    """Why ``ros2 param set /simulator use_sim_time true`` is refused, or None for false."""
    return f'refused: the simulator {IS_THE_CLOCK}' if use_sim_time else None


class SimulatorNode(Node):
    """Runs a plant (``sphere_sim.twin.plants``) through
    :class:`sphere_sim.twin.runner.TwinRunner`.

    Parameters
    ----------
    plant : sphere_sim.twin.plants.TwinPlant, optional
        Overrides the ``plant``/``scene``/``table`` parameters (for tests).
    **node_kwargs
        Passed to ``rclpy.node.Node`` (e.g. ``context``).
    """

    def __init__(self, plant: TwinPlant | None = None, **node_kwargs: Any) -> None:
        from sphere_sim.twin.plant_setup import (
            build_plant,
            fidelity_check,
            plant_and_fidelity,
            plant_rung,
        )
        from sphere_sim.twin.precompile import announce_compile
        from sphere_sim.twin.runner import TwinRunner

        super().__init__('simulator', **node_kwargs)
        if self.get_parameter('use_sim_time').value:
            raise StartupError(f'the simulator {IS_THE_CLOCK}')
        p = self._declare_parameters()
        self.publish_rate_hz = p['publish_rate_hz']
        self.period_s = 1.0 / self.publish_rate_hz
        self.real_time_factor = p['real_time_factor']
        # Checked before the seconds of the build: a plant and a fidelity that disagree.
        kind, fidelity = plant_and_fidelity(p['plant'], p['fidelity'])
        if plant is None:
            # A cold numba cache is compiled here, said in a line before and after.
            with announce_compile(self.get_logger().info):
                plant = build_plant(kind, p['scene'], [t for t in p['tables'] if t],
                                    p['params'], fidelity)
        # The full model beside the plant: its own process, on the spare core.
        check = (fidelity_check(p['scene'], p['params'], self.period_s)
                 if p['check_fidelity'] else None)
        self.runner = TwinRunner(plant, self.period_s, p['noise_std_rad'], p['seed'],
                                 p['lockstep'], check=check)
        self.rung = plant_rung(plant)
        self._topic_publishers = {topic.name: self.create_publisher(
            topic.msg_type, topic.name, topic.qos.to_profile())
            for topic in (SURFACE_NORMAL, SPHERE_STATE, BEAM_STATE, BEAM_VOLTAGE, MARKERS,
                          CLOCK, PROGRAMME_STATUS)}
        # A status for each listener that joins: a recorder whose /diagnostics reader is
        # matched after simulated time starts (discovery matches each topic on its own) then
        # still hears how the physics is integrated before the next status period.
        self._topic_publishers[DIAGNOSTICS.name] = self.create_publisher(
            DIAGNOSTICS.msg_type, DIAGNOSTICS.name, DIAGNOSTICS.qos.to_profile(),
            event_callbacks=PublisherEventCallbacks(matched=self.on_diagnostics_matched))
        self._tf_type = tf_message_type()
        self._tf_publisher = (None if self._tf_type is None else
                              self.create_publisher(self._tf_type, TF_TOPIC, TF_QUEUE_DEPTH))
        if self._tf_type is None:
            self.get_logger().info(NO_TF_LINE)
        # Every message leaves through one thread of its own, in the order it was made: the
        # next sample integrates (the kernel releases the GIL) while this one is published.
        self._outbox = Outbox(name='simulator publishing', on_error=self._publishing_failed)
        # A command the transport loses never reaches a callback: the QoS event counts it
        # (Fast DDS reports what a sender's queue gave up before this reader had it; the
        # reader's own queue is deep enough not to overflow: msg_defs.topics.COMMAND_QOS).
        lost_events = SubscriptionEventCallbacks(message_lost=self.on_commands_lost)
        self.create_subscription(VOLTAGE_COMMAND.msg_type, VOLTAGE_COMMAND.name,
                                 self.on_voltage_command, VOLTAGE_COMMAND.qos.to_profile(),
                                 event_callbacks=lost_events)
        self.create_subscription(PULSE_PROGRAM.msg_type, PULSE_PROGRAM.name,
                                 self.on_pulse_program, PULSE_PROGRAM.qos.to_profile(),
                                 event_callbacks=lost_events)
        self.lockstep = p['lockstep']
        self._sample_timer: Any = None
        self._start_sample_timer()
        self.create_timer(STATUS_PERIOD_S, self.on_status_timer)
        self.wait_for_subscribers = p['wait_for_subscribers']
        self.wait_for_clock_subscribers = p['wait_for_clock_subscribers']
        self._last_sample: Sample | None = None
        self._reports = ReportLimit()
        # Late programmes: the first logged with its times, the others counted and summarised.
        self._late = CountedWarning()
        self._last_repeat_wall_s = 0.0
        self._wall_start_s = time.perf_counter()
        # The publishing thread's busy and blocked seconds when simulated time started: what it
        # spent before, while the node waited for its subscribers, is not the run's (counted in,
        # a loaded machine once read 0.81 s of publishing in an unpaced run of 0.69 s).
        self._outbox_at_start = (0.0, 0.0)
        # (wall, simulated) time from which the pace is kept: the first sample, or the last
        # change of the real-time factor.
        self._pace_anchor = (self._wall_start_s, 0.0)
        self.get_logger().info(
            f'{DISCOVERY_RANGE_VAR}={os.environ.get(DISCOVERY_RANGE_VAR, "(unset)")}, domain id '
            f'{self.context.get_domain_id()}; {kind} plant, model {self.rung}, scene '
            f'{p["scene"]}, {self.publish_rate_hz:g} Hz, real-time factor '
            f'{self.real_time_factor:g}'
            f'{", lockstep" if p["lockstep"] else ""}; publishing {SURFACE_NORMAL.name}')

    def _declare_parameters(self) -> dict[str, Any]:
        parameters = declare_node_parameters(self, SIMULATOR_PARAMETERS)
        # Following /clock, which its own sampling publishes, would stop it for good.
        accept_parameter_changes(self, SIMULATOR_PARAMETERS, self._parameter_changed,
                                 refuse={'use_sim_time': _clock_follower})
        return parameters

    def _start_sample_timer(self) -> None:
        """(Re)start the sampling timer for the current pace and period."""
        if self._sample_timer is not None:
            self.destroy_timer(self._sample_timer)
        self.paced = self.real_time_factor > 0 and not self.lockstep
        period = (self.period_s / self.real_time_factor / CATCH_UP_SPEEDUP if self.paced
                  else FAST_TIMER_PERIOD_S)
        self._sample_timer = self.create_timer(period, self.on_timer)

    def _parameter_changed(self, name: str, value: Any) -> None:
        """Take a ``ros2 param set`` of a settable parameter (already checked)."""
        if name == 'noise_std_rad':
            self.runner.set_noise(value)
        else:
            if name == 'publish_rate_hz':
                self.publish_rate_hz, self.period_s = value, 1.0 / value
                self.runner.set_period(self.period_s)
            else:  # real_time_factor
                self.real_time_factor = value
                # The new pace counts from the simulated now: no burst to catch up.
                self._pace_anchor = (time.perf_counter(), self.runner.time_s)
            self._start_sample_timer()  # its period follows both
        self.get_logger().info(f'{name} set to {value:g}')

    # --- commands ----------------------------------------------------------------------
    def on_diagnostics_matched(self, info: QoSPublisherMatchedInfo) -> None:
        # Before simulated time starts, the status sent at its start reaches this listener.
        if info.current_count_change > 0 and self.runner.counters.samples > 0:
            self._publish_diagnostics(DiagnosticStatus.OK, 'running')

    def on_commands_lost(self, info: QoSMessageLostInfo) -> None:
        """Count the commands the transport lost before they reached this node."""
        self.runner.counters.lost += info.total_count_change

    def on_voltage_command(self, msg: Any) -> None:
        self.runner.counters.received += 1
        # ValueError covers both the contract (conversions) and the runner's CommandRejectedError.
        try:
            cut = self.runner.command_voltages(voltages_from_msg(msg))
            if cut is not None:
                self._report(DiagnosticStatus.WARN, cut)
        except ValueError as error:
            self.runner.counters.rejected += 1
            self._report_rejection(VOLTAGE_COMMAND.name, str(error))
        self._publish_events()

    def on_pulse_program(self, msg: Any) -> None:
        self.runner.counters.received += 1
        start_s = ns_from_time(msg.header.stamp) / NS_PER_S
        try:
            times, volts = programme_from_msg(msg)
        except ValueError as error:
            self.runner.refuse_programme(start_s, str(error))
            self.runner.counters.rejected += 1
            self._report_rejection(PULSE_PROGRAM.name, str(error))
            self._publish_events()
            return
        try:
            late = self.runner.counters.late
            self.runner.command_programme(times, volts, start_s)
            if self.runner.counters.late > late and self._late.note():
                self.get_logger().warning(
                    f'{PULSE_PROGRAM.name} for t = {start_s:.4f} s arrived at t = '
                    f'{self.runner.time_s:.4f} s: started late, at the next sample '
                    f'({self._late_cause()}); the next late ones are counted, in a line at '
                    f'most every {self._late.period_s:g} s')
        except ValueError as error:
            self.runner.counters.rejected += 1
            self._report_rejection(PULSE_PROGRAM.name, str(error))
        self._publish_events()

    def _publish_events(self) -> None:
        """Echo what happened to programmes since the last echo, oldest first."""
        events = self.runner.take_events()
        if events:
            self._outbox.submit(self._send_events, events)

    def _send_events(self, events: Sequence[ProgrammeEvent]) -> None:
        publisher = self._topic_publishers[PROGRAMME_STATUS.name]
        for event in events:
            publisher.publish(programme_event_to_msg(event))

    def _publishing_failed(self, error: BaseException) -> None:
        # After a shutdown signal the context is gone and a publish fails: that is the
        # shutdown. Before it, a failed publish is a bug, said once per kind.
        if not self.context.ok():
            return
        self.get_logger().error(f'publishing failed: {type(error).__name__}: {error}',
                                once=True)

    def _report_rejection(self, topic: str, reason: str) -> None:
        """Report a rejection (already counted)."""
        self._report(DiagnosticStatus.ERROR, f'rejected {topic}: {reason}')

    def _report(self, level: bytes, text: str) -> None:
        """Log and publish a rejection or a cut programme, at most REPORTS_PER_WINDOW a
        second; the next report says how many were left out (the status counts them all)."""
        if not self._reports.allow():
            return
        left_out = self._reports.take_suppressed()
        text += f' ({left_out} more reports left out)' if left_out else ''
        # Two call sites: rclpy refuses a severity that changes at one.
        if level == DiagnosticStatus.ERROR:
            self.get_logger().error(text)
        else:
            self.get_logger().warning(text)
        self._publish_diagnostics(level, text)

    def _late_cause(self) -> str:
        """Why a programme arrives after its start, in words."""
        if self.lockstep:
            return 'its stamp was in the simulated past'
        if not self.paced:
            return ('the simulator had passed its start: unpaced, it runs on while the sender '
                    'answers')
        return (f'the simulator had passed its start: answering a sample took more than a '
                f'sample period of wall time, {1e3 * self.period_s / self.real_time_factor:.0f} '
                f'ms at real-time factor {self.real_time_factor:g}')

    def _summarise_late(self) -> None:
        """Say how many programmes started late since the last line, at most once per
        SUMMARY_PERIOD_S of wall time (the status and the final line count every one)."""
        summary = self._late.due()
        if summary is not None:
            self.get_logger().warning(
                f'{summary.count} more programmes on {PULSE_PROGRAM.name} arrived after their '
                f'start in the last {summary.since_s:.0f} s of wall time and started late, at '
                f'the next sample ({self._late_cause()}); {summary.total} late in all')

    def on_status_timer(self) -> None:
        self._summarise_late()
        state = 'waiting for subscribers' if self._waiting() else 'running'
        left_out = self._reports.take_suppressed()  # a burst that ended: its count is said here
        self._publish_diagnostics(DiagnosticStatus.OK, state + (
            f' ({left_out} more reports left out)' if left_out else ''))

    def status_values(self) -> tuple[tuple[str, int | str], ...]:
        """The figures of the periodic status: counters, time, real-time factor, where the
        wall time went (fractions) and programme latency (ms)."""
        c, t, out = self.runner.counters, self.runner.timings, self._outbox
        wall = max(time.perf_counter() - self._wall_start_s, 1e-9)
        median_ms, max_ms = (1e3 * v for v in t.latency_summary())
        return (
            # Every command received is accepted (applied), rejected (refused), dropped as
            # replaced, or still waiting; the lost ones never arrived (TwinCounters).
            ('received', c.received), ('accepted', c.accepted), ('rejected', c.rejected),
            ('dropped', c.dropped), ('dropped_replaced', c.replaced), ('dropped_lost', c.lost),
            ('waiting', self.runner.waiting), ('programmes', c.programmes),
            ('late', c.late), ('cut', c.cut), ('samples', c.samples),
            ('simulated_time_s', f'{self.runner.time_s:.6f}'), ('wall_time_s', f'{wall:.6f}'),
            ('real_time_factor', f'{self.runner.time_s / wall:.4f}'),
            # The simulation thread's wall time: integrating, and waiting for the publishing
            # thread to take a sample; the publishing thread's: building and sending messages.
            ('integrating_fraction', f'{t.integrating_s / wall:.4f}'),
            ('waiting_for_publishing_fraction',
             f'{(out.waiting_s - self._outbox_at_start[1]) / wall:.4f}'),
            ('publishing_fraction', f'{(out.busy_s - self._outbox_at_start[0]) / wall:.4f}'),
            ('programme_latency_median_ms', f'{median_ms:.3f}'),
            ('programme_latency_max_ms', f'{max_ms:.3f}'),
            ('programme_delay_median_ms', f'{1e3 * t.delay_median_s():.3f}'),
            # The rung of the ladder of models that served every kick (all the run's
            # programmes: one rung a run), and, with check_fidelity, how far its landings
            # were from the full model's.
            ('fidelity', self.rung), *self._integration_values(), *self._fidelity_values())

    def _integration_values(self) -> tuple[tuple[str, str], ...]:
        # How the physics is integrated, so that a replay of the bag integrates it alike
        # (run_analysis.recorded_integration); the kick table integrates nothing.
        from sphere_sim.twin.plants import ContinuousPlant

        plant = self.runner.plant
        if not isinstance(plant, ContinuousPlant):
            return ()
        return (('integration_method', plant.method), ('integration_rtol', f'{plant.rtol:g}'))

    def _fidelity_values(self) -> tuple[tuple[str, int | str], ...]:
        check = self.runner.check
        if check is None:
            return ()
        d = check.divergence()
        return (('fidelity_checked', d.checked), ('fidelity_pending', d.pending),
                ('fidelity_skipped', d.skipped),
                ('fidelity_divergence_median_rad', f'{d.median_rad:.3e}'),
                ('fidelity_divergence_max_rad', f'{d.max_rad:.3e}'))

    def _publish_diagnostics(self, level: bytes, message: str) -> None:
        status = DiagnosticStatus(level=level, name='simulator: commands',
                                  hardware_id='sphere_twin', message=message)
        status.values = [KeyValue(key=k, value=str(v)) for k, v in self.status_values()]
        array = DiagnosticArray(status=[status])
        array.header.stamp = time_from_ns(round(self.runner.time_s * NS_PER_S))
        self._outbox.submit(self._topic_publishers[DIAGNOSTICS.name].publish, array)

    # --- time --------------------------------------------------------------------------
    def _waiting(self) -> bool:
        return bool(self.wait_for_subscribers or self.wait_for_clock_subscribers)

    def _subscribers_present(self) -> bool:
        pub = self._topic_publishers
        return (pub[SURFACE_NORMAL.name].get_subscription_count() >= self.wait_for_subscribers
                and pub[CLOCK.name].get_subscription_count() >= self.wait_for_clock_subscribers)

    def on_timer(self) -> None:
        if self._waiting():
            if not self._subscribers_present():
                return
            self.get_logger().info(
                f'{self.wait_for_subscribers} subscribers on {SURFACE_NORMAL.name} and '
                f'{self.wait_for_clock_subscribers} on {CLOCK.name}: simulated time starts')
            self.wait_for_subscribers = self.wait_for_clock_subscribers = 0
        if self.runner.counters.samples == 0:
            self._wall_start_s = time.perf_counter()  # simulated time 0 is now
            self._pace_anchor = (self._wall_start_s, 0.0)
            self._outbox_at_start = (self._outbox.busy_s, self._outbox.waiting_s)
            # At once, not a status period later: a recording from the start then says how the
            # physics is integrated (a replay integrates alike), however short the run.
            self._publish_diagnostics(DiagnosticStatus.OK, 'running')
        elif self.paced and self.runner.time_s - self._pace_anchor[1] >= (
                time.perf_counter() - self._pace_anchor[0]) * self.real_time_factor:
            return  # ahead of the wall clock
        sample, refused = self.runner.tick()
        for reason in refused:
            self._report_rejection('plant', reason)
        self._publish_events()  # before the sample: a controller has them when it decides
        if sample is None:
            now = time.perf_counter()
            if self._last_sample is not None and \
                    now - self._last_repeat_wall_s > IDLE_REPEAT_PERIOD_S:
                self._last_repeat_wall_s = now
                self._outbox.submit(self._publish, self._last_sample, False)
            return
        self._last_sample = sample
        self._outbox.submit(self._publish_sample, sample,
                            self.runner.counters.samples % MARKER_EVERY_N_SAMPLES == 1)

    def _publish_sample(self, sample: Sample, markers: bool) -> None:
        self._publish(sample, markers)
        self.runner.timings.record_published(sample, time.perf_counter())

    def _publish(self, sample: Sample, markers: bool) -> None:
        snap = sample.snapshot
        stamp = time_from_ns(round(snap.time_s * NS_PER_S))
        pub = self._topic_publishers
        pub[CLOCK.name].publish(Clock(clock=stamp))
        pub[SURFACE_NORMAL.name].publish(surface_normal_to_msg(sample.measured_normal, stamp))
        pub[BEAM_VOLTAGE.name].publish(voltages_to_msg(snap.voltages_v, stamp))
        if snap.sphere is not None:
            centre, quaternion, velocity, omega = snap.sphere
            pub[SPHERE_STATE.name].publish(sphere_state_to_msg(centre, quaternion, velocity,
                                                               omega, stamp=stamp))
            if self._tf_publisher is not None and self._tf_type is not None:
                self._tf_publisher.publish(self._tf_type(
                    transforms=[sphere_transform_msg(centre, quaternion, stamp)]))
        if snap.beams is not None:
            z, phi, z_rate, phi_rate = snap.beams
            pub[BEAM_STATE.name].publish(beam_state_to_msg(z, phi, z_rate, phi_rate,
                                                           stamp=stamp))
        if markers:
            beams = snap.beams if snap.beams is not None else (None, None)
            position = snap.sphere[0] if snap.sphere is not None else None
            pub[MARKERS.name].publish(twin_markers(snap.normal, stamp, position, beams[0],
                                                   beams[1]))

    def summary(self) -> str:
        """The final line: simulated time, samples, programmes started, commands rejected,
        dropped and still waiting for their start, real-time factor, and where each thread's
        wall time went."""
        self._outbox.flush()  # what was handed over counts as published
        if self.runner.check is not None:
            self.runner.check.close(wait=True)  # the kicks that landed are all compared
        v = dict(self.status_values())
        return (f'simulator: simulated {self.runner.time_s:.3f} s, {v["samples"]} samples, '
                f'{v["programmes"]} programmes started ({v["late"]} late), commands: '
                f'{v["rejected"]} rejected, {v["dropped"]} dropped, {v["waiting"]} waiting for '
                'their sample; '
                f'real-time factor {float(v["real_time_factor"]):.3f}; of wall time: '
                f'integrating {float(v["integrating_fraction"]):.0%} and waiting for '
                f'publishing {float(v["waiting_for_publishing_fraction"]):.0%} (simulation '
                f'thread), publishing {float(v["publishing_fraction"]):.0%} (publishing thread)'
                f'; model {v["fidelity"]}' + self._fidelity_text(v))

    @staticmethod
    def _fidelity_text(v: dict[str, int | str]) -> str:
        if 'fidelity_checked' not in v:
            return ''
        from sphere_sim.integrate.tolerances import CHECK_RTOL

        return (f'; fidelity check: {v["fidelity_checked"]} kicks against the full model '
                f'(rtol {CHECK_RTOL:g}), divergence median {v["fidelity_divergence_median_rad"]}'
                f' rad, max {v["fidelity_divergence_max_rad"]} rad ({v["fidelity_skipped"]} '
                f'skipped, {v["fidelity_pending"]} unfinished)')

    def destroy_node(self) -> None:
        # The queued messages go out (or, after a shutdown signal, fail quietly) before the
        # publishers they use are destroyed.
        self._outbox.close()
        if self.runner.check is not None:
            self.runner.check.close()
        super().destroy_node()


def main(args: list[str] | None = None) -> int:
    return run_node(SimulatorNode, args, farewell=SimulatorNode.summary, name='simulator',
                    parameters=SIMULATOR_PARAMETERS)


if __name__ == '__main__':
    sys.exit(main())
