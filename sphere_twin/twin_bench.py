"""The live twin's speed and kick cycle: simulator, reference and controller as processes over
DDS.

Runs the demo's scenario (the Fig. 13 setpoint, then eq. (64)) without a recorder, the
simulator unpaced (``real_time_factor`` 0: as fast as it can) or paced, for a fixed span of
simulated time, and reads the simulator's periodic status on ``/diagnostics``: the real-time
factor it achieved, where its wall time went (integrating, publishing, rclpy and the rest) and
how long a pulse programme took from its arrival to the published sample that first shows it;
and the kick cycle from the simulator's reports of each programme's start
(``/beams/programme_status``) and the controller's decisions. The CLI (``sphere-twin bench
twin``) prints and writes; this module measures and returns.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from sphere_twin.processes import fresh_domain_id, running_nodes
from sphere_twin.scenario import scenario_nodes

DEFAULT_DURATION_S = 20.0
# The scenario's setpoint phase, shorter than the demo's: the bench wants kicks, and the
# trajectory phase keeps the controller kicking.
SETPOINT_S = 4.0
# Subscribers of /sphere/surface_normal the simulator waits for: the controller and the probe.
NORMAL_SUBSCRIBERS = 2
# Subscribers of /clock it waits for: the reference (on simulated time).
CLOCK_SUBSCRIBERS = 1
START_TIMEOUT_S = 60.0
# An unpaced run slower than this many wall seconds per simulated second is cut.
WALL_PER_SIMULATED_LIMIT = 10.0


@dataclasses.dataclass(frozen=True)
class TwinBenchResult:
    """The simulator's figures at the end of a run (``pace`` 0: unpaced)."""

    plant: str
    simulated_s: float
    wall_s: float
    real_time_factor: float
    programmes: int
    late: int
    rejected: int
    samples: int
    integrating_fraction: float
    publishing_fraction: float
    latency_median_ms: float
    latency_max_ms: float
    cycle: LoopCycle | None = None
    pace: float = 0.0
    waiting_fraction: float = 0.0
    # The rung of the ladder of models that served the kicks ('' in results written before
    # the simulator said it).
    fidelity: str = ''

    @property
    def pace_name(self) -> str:
        return 'unpaced' if self.pace == 0.0 else f'paced at {self.pace:g}'

    @property
    def other_fraction(self) -> float:
        """The simulation thread's rest: rclpy (executor, callbacks, command conversion), the
        wait for the wall clock when paced, and everything else. Publishing runs on a thread
        of its own, so its share is not part of this one's."""
        return 1.0 - self.integrating_fraction - self.waiting_fraction

    @property
    def kicks_per_simulated_s(self) -> float:
        return self.programmes / self.simulated_s if self.simulated_s > 0 else math.nan

    def to_dict(self) -> dict[str, Any]:
        return {**dataclasses.asdict(self), 'other_fraction': self.other_fraction,
                'kicks_per_simulated_s': self.kicks_per_simulated_s}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> TwinBenchResult:
        fields = {k: v for k, v in data.items() if k in cls.__dataclass_fields__}
        if fields.get('cycle') is not None:
            fields['cycle'] = LoopCycle(**fields['cycle'])
        return cls(**fields)

    @classmethod
    def from_status(cls, plant: str, values: Mapping[str, str], cycle: LoopCycle | None = None,
                    pace: float = 0.0) -> TwinBenchResult:
        """From the key-values of the simulator's ``/diagnostics`` status."""
        return cls(plant, float(values['simulated_time_s']), float(values['wall_time_s']),
                   float(values['real_time_factor']), int(values['programmes']),
                   int(values['late']), int(values['rejected']), int(values['samples']),
                   float(values['integrating_fraction']), float(values['publishing_fraction']),
                   float(values['programme_latency_median_ms']),
                   float(values['programme_latency_max_ms']), cycle, pace,
                   float(values['waiting_for_publishing_fraction']), values.get('fidelity', ''))


@dataclasses.dataclass(frozen=True)
class LoopCycle:
    """The node loop's kick cycle (medians, ms): from one programme's actual start to the next,
    in simulated and wall time, and its parts in simulated time: the simulator's delay of the
    start after the one asked for, the kick in effect until the controller decided on the
    sample that ends it, and the lead the controller gives the next start after that sample."""

    simulated_ms: float
    wall_ms: float
    start_delay_ms: float
    settling_ms: float
    lead_ms: float

    @classmethod
    def measure(cls, asked_s: Sequence[float], started_s: Sequence[float],
                started_wall_s: Sequence[float],
                decisions_s: Sequence[float]) -> LoopCycle | None:
        """From the simulator's reports of the programmes' starts (the start each asked for
        and the one it got, simulated s, and when the report reached an observer, wall s) and
        the stamps of the samples kicks were decided on (simulated s).

        Each start is matched to the decision just before its asked start (its own) and to
        the first one after its actual start (the next kick's), not by position, so a status
        the observer missed in a fast stream shifts nothing.
        """
        asked, started = np.asarray(asked_s), np.asarray(started_s)
        decisions = np.sort(np.asarray(decisions_s))
        own = np.searchsorted(decisions, asked - 1e-9, side='right') - 1
        following = np.searchsorted(decisions, started - 1e-9, side='left')
        paired = (own >= 0) & (following < decisions.size)
        if np.count_nonzero(paired) < 2:
            return None
        return cls(*(1e3 * float(np.median(v)) for v in (
            np.diff(started), np.diff(np.asarray(started_wall_s)), started - asked,
            decisions[following[paired]] - started[paired],
            asked[paired] - decisions[own[paired]])))


class BenchError(RuntimeError):
    """The run did not get going or did not finish."""


def _simulator_status(diagnostics: Sequence[Any]) -> dict[str, str]:
    """Key-values of the simulator's newest status, or {} before one."""
    for msg in reversed(diagnostics):
        status = msg.status[0]
        if status.name.startswith('simulator'):
            from msg_defs.conversions import status_values

            return status_values(status)
    return {}


def run_twin_bench(plant: str = 'continuous', duration_s: float = DEFAULT_DURATION_S,
                   seed: int = 0, progress: Callable[[float], object] | None = None,
                   real_time_factor: float = 0.0,
                   fidelity: str = '') -> tuple[TwinBenchResult, str]:
    """Run the loop (unpaced, or paced at ``real_time_factor``) until the simulator reports
    ``duration_s`` of simulated time, on the rung ``fidelity`` of the ladder of models ('' for
    the plant's own).

    ``progress(simulated_s)`` is called as the status comes in. Returns a
    :class:`TwinBenchResult` and the simulator's farewell line.

    Raises
    ------
    BenchError
        When the loop does not start, or the run does not finish in time.
    """
    from msg_defs.conversions import programme_events_from_msg, status_values
    from msg_defs.programme_events import ProgrammeState
    from msg_defs.topics import CONTROLLER_STATUS, DIAGNOSTICS, PROGRAMME_STATUS, SURFACE_NORMAL
    from sphere_twin.scenario import RunLog
    from sphere_twin.testing import TopicProbe, TwinTimeoutError

    domain_id = fresh_domain_id()
    *others, simulator = scenario_nodes(SETPOINT_S, plant, real_time_factor, seed,
                                        NORMAL_SUBSCRIBERS, CLOCK_SUBSCRIBERS,
                                        fidelity=fidelity)
    with running_nodes(*others, domain_id=domain_id) as group:
        probe = TopicProbe(domain_id, (SURFACE_NORMAL, CONTROLLER_STATUS, DIAGNOSTICS))
        diagnostics = probe.messages[DIAGNOSTICS.name]
        # (asked start, actual start in simulated s, wall s at arrival)
        starts: list[tuple[float, float, float]] = []

        def on_programme_status(msg: Any) -> None:
            starts.extend((e.asked_s, e.time_s, time.monotonic())
                          for e in programme_events_from_msg(msg)
                          if e.state is ProgrammeState.STARTED)

        probe.node.create_subscription(PROGRAMME_STATUS.msg_type, PROGRAMME_STATUS.name,
                                       on_programme_status, PROGRAMME_STATUS.qos.to_profile())

        def finished() -> bool:
            status = _simulator_status(diagnostics)
            simulated = float(status.get('simulated_time_s', 0.0))
            if progress is not None and status:
                progress(simulated)
            return simulated >= duration_s

        try:
            probe.spin_until(RunLog(probe).controller_ready, START_TIMEOUT_S,
                             'controller holding the reference')
            process = group.start(simulator.executable, simulator.args)
            probe.process = process
            wall_per_simulated = max(WALL_PER_SIMULATED_LIMIT, 3.0 / (real_time_factor or 1.0))
            probe.spin_until(finished, START_TIMEOUT_S + wall_per_simulated * duration_s,
                             f'{duration_s:g} s of simulated time')
        except TwinTimeoutError as error:
            raise BenchError(str(error).splitlines()[0]) from None
        finally:
            probe.close()
        status = _simulator_status(diagnostics)
        decisions = [float(t) for m in probe.messages[CONTROLLER_STATUS.name]
                     for t in status_values(m.status[0]).get('kicked_s', '').split()]
    farewell = next((line for line in process.stdout_text().splitlines()
                     if line.startswith('simulator:')), '')
    cycle = None
    if starts:
        asked, started, started_wall = zip(*starts, strict=True)
        cycle = LoopCycle.measure(asked, started, started_wall, decisions)
    return TwinBenchResult.from_status(plant, status, cycle, real_time_factor), farewell


def summary_lines(result: TwinBenchResult) -> list[str]:
    """What ``sphere-twin bench twin`` prints; the last line is the headline."""
    r = result
    return [
        f'simulator ({r.plant} plant, {r.pace_name}): {r.simulated_s:.2f} s simulated in '
        f'{r.wall_s:.2f} s wall, {r.programmes} programmes ({r.kicks_per_simulated_s:.1f} per '
        f'simulated second), {r.rejected} rejected, {r.samples} samples',
        f'wall time of the simulation thread: integrating {r.integrating_fraction:.1%}, '
        f'waiting for the publishing thread {r.waiting_fraction:.1%}, rclpy and the rest '
        f'{r.other_fraction:.1%}; the publishing thread busy {r.publishing_fraction:.1%}',
        f'programme latency, arrival to the first published sample showing it: median '
        f'{r.latency_median_ms:.2f} ms, largest {r.latency_max_ms:.2f} ms (wall)',
        *([] if r.cycle is None else [
            f'node loop cycle, actual start to actual start (medians): '
            f'{r.cycle.simulated_ms:.1f} ms simulated, {r.cycle.wall_ms:.1f} ms wall; in '
            f'simulated time the start delayed {r.cycle.start_delay_ms:.1f} ms, the kick in '
            f'effect until the deciding sample {r.cycle.settling_ms:.1f} ms, the lead to the '
            f'next start {r.cycle.lead_ms:.1f} ms']),
        f'twin real-time factor: {r.real_time_factor:.2f} {r.pace_name} ({r.plant}, '
        f'{r.fidelity or "rung unreported"})',
    ]
