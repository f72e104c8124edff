"""The closed-loop scenario the demo and ``bench twin`` run: the Fig. 13 setpoint, then the
trajectory of eq. (64); which nodes it takes, what a run's observer reads off it, and the same
scenario as an offline closed loop (no ROS), the yardstick of the node loop."""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, cast

from msg_defs.device import NS_PER_S
from sphere_twin.processes import NodeSpec, parameter_args

if TYPE_CHECKING:
    import numpy as np
    from numpy.typing import NDArray

    from sphere_control.closed_loop import LoopHistory
    from sphere_control.reference import ScheduledReference
    from sphere_sim.twin.plants import ContinuousPlant
    from sphere_twin.testing import TopicProbe

SETPOINT_XY = (0.01, 0.02)  # Fig. 13
CONTROLLER = 'extended'
# Eq. (64) entered where it passes the centre (t = 1/(4 f1)), so the trajectory takes over from
# the setpoint without a jump to A_max.
TRAJECTORY_OFFSET_S = 12.5


def scenario_nodes(setpoint_s: float, plant: str, real_time_factor: float, seed: int,
                   normal_subscribers: int, clock_subscribers: int,
                   check_fidelity: bool = False, fidelity: str = '') -> tuple[NodeSpec, ...]:
    """The closed loop of the scenario, in start order: controller, reference, simulator.

    The simulator comes last, once the controller holds the reference, and holds simulated
    time at 0 until ``normal_subscribers`` listen to the normal and ``clock_subscribers`` to
    ``/clock``: the scenario's clock (simulated time, which the reference follows) starts when
    everyone is there. ``clock_subscribers`` counts every listener of ``/clock``, the reference
    and a recorder (which records it) alike: the simulator sees only a count, so with a
    recorder a count of 1 would let time start before the reference listens. DDS discovery
    of one pair of processes can lag the others by seconds (up to 3 s seen here), longer than
    a short run: a reference that had not yet heard the clock would hold its setpoint
    through it.
    """
    reference_args = dict(setpoint_xy=list(SETPOINT_XY), trajectory_start_s=setpoint_s,
                          trajectory_offset_s=TRAJECTORY_OFFSET_S, use_sim_time=True)
    return (
        NodeSpec('controller', tuple(parameter_args(controller=CONTROLLER))),
        NodeSpec('reference', tuple(parameter_args(**reference_args))),
        NodeSpec('simulator', tuple(parameter_args(
            plant=plant, **({'fidelity': fidelity} if fidelity else {}), seed=seed,
            real_time_factor=real_time_factor,
            wait_for_subscribers=normal_subscribers,
            wait_for_clock_subscribers=clock_subscribers, check_fidelity=check_fidelity))),
    )


class RunLog:
    """What the demo watches while the run goes: measured normals and controller status."""

    def __init__(self, probe: TopicProbe) -> None:
        from msg_defs.topics import CONTROLLER_STATUS, SURFACE_NORMAL

        self.normals = probe.messages[SURFACE_NORMAL.name]
        self.statuses = probe.messages[CONTROLLER_STATUS.name]

    def simulated_s(self) -> float:
        from msg_defs.conversions import ns_from_time

        return ns_from_time(self.normals[-1].header.stamp) / NS_PER_S if self.normals else 0.0

    def controller_ready(self) -> bool:
        """The controller has the reference and waits for the first sample."""
        return any(m.status[0].message == 'no state' for m in self.statuses[-3:])

    def kicks(self) -> int:
        from msg_defs.conversions import status_values

        for msg in reversed(self.statuses):
            values = status_values(msg.status[0])
            if 'kicks' in values:
                return int(values['kicks'])
        return 0


def scenario_reference(setpoint_s: float) -> ScheduledReference:
    """The reference node's schedule in the scenario: the setpoint, then eq. (64)."""
    from sphere_control.reference import CircleTrajectory, ScheduledReference, Setpoint

    return ScheduledReference(Setpoint(SETPOINT_XY), CircleTrajectory(), setpoint_s,
                              TRAJECTORY_OFFSET_S)


class _WatchedReference:
    """A reference that tells ``on_time`` each time it is sampled at: how far a closed loop
    has got, from outside it (the loop has no callback of its own). ``on_time`` may raise to
    end the loop early."""

    def __init__(self, reference: ScheduledReference, on_time: Callable[[float], None]) -> None:
        self._reference = reference
        self._on_time = on_time

    @property
    def is_constant(self) -> bool:
        return self._reference.is_constant

    def xy_at(self, time_s: float) -> NDArray[np.float64]:
        self._on_time(time_s)
        return self._reference.xy_at(time_s)

    def velocity_xy(self, time_s: float) -> NDArray[np.float64]:
        return self._reference.velocity_xy(time_s)


def offline_loop(setpoint_s: float, duration_s: float, plant: str = 'continuous',
                 on_time: Callable[[float], None] | None = None,
                 fidelity: str = '') -> LoopHistory:
    """The scenario as an offline closed loop (:func:`~sphere_control.closed_loop.run_closed_loop`):
    the controller node's controller and kick period, the simulator's plant (on the rung
    ``fidelity`` of the ladder of models, '' for the plant's own) from its initial state (the
    continuous one carrying its state from kick to kick), the reference node's schedule.
    Returns the :class:`~sphere_control.closed_loop.LoopHistory`.

    ``on_time`` is called with the simulated time of every step (progress; it may raise to
    stop the loop).
    """
    from sphere_control.closed_loop import LoopSettings, run_closed_loop
    from sphere_control.controllers import controller_for
    from sphere_control.intensity_calibration import IntensityCalibration
    from sphere_sim.kicks.discrete import kick_period_s
    from sphere_sim.kicks.lookup_table import load_kick_model
    from sphere_sim.twin.plant_setup import build_plant, plant_and_fidelity
    from sphere_sim.twin.plants import TwinKickPlant

    plant, fidelity = plant_and_fidelity(plant, fidelity)
    kicks = load_kick_model()
    calibration = IntensityCalibration.of(kicks)
    period_s = kick_period_s(kicks)
    twin = build_plant(plant, fidelity=fidelity)
    start = twin.snapshot().normal
    # The continuous kind builds a ContinuousPlant.
    kick_plant = calibration.applied_to(TwinKickPlant(kicks, cast('ContinuousPlant', twin),
                                                      period_s)
                                        if plant == 'continuous' else kicks)
    settings = LoopSettings(max_steps=round(duration_s / period_s), kick_period_s=period_s)
    reference = scenario_reference(setpoint_s)
    return run_closed_loop(controller_for(CONTROLLER, calibration.applied_to(kicks)), kick_plant,
                           start, reference if on_time is None
                           else _WatchedReference(reference, on_time), settings)
