"""Running an experiment protocol (``sphere_sim.fitting.protocol``) on a device: the one loop
"probe, rest, observe" that every driver shares.

A device is anything that can start a pulse programme at its next sample and hand back the
measured normals of the samples that follow (:class:`ProtocolDevice`): the synthetic device's
runner in this process, recorded into a bag (:func:`record_protocol`), or a device on the ROS
topics (``sphere_twin.protocol_wire.TopicDevice``, ``sphere-twin experiment``). The loop sends
each probe of a threshold search, lets the sphere settle, compares the resting normals after it
with those before it (:func:`~sphere_sim.fitting.protocol.pulled_in`) and feeds the bisection;
sends the ramps and the kicks as they are; and reports the steps that need a measurement the
device does not publish.
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING
from typing import Protocol as TypingProtocol

import numpy as np

from sphere_sim.kicks.discrete import NOISE_STUDY_STD_RAD
from sphere_twin.synthetic_device import PUBLISH_RATE_HZ

if TYPE_CHECKING:
    from numpy.typing import NDArray

    from sphere_sim.fitting.protocol import FrictionKicks, Protocol, ThresholdSearch
    from sphere_sim.model.parameters import ParameterSet
    from sphere_sim.model.programme import PulseProgramme
    from sphere_twin.protocol_bag import ProtocolResults
    from sphere_twin.synthetic_device import DeviceRecording

Bracket = tuple[float | None, float | None]


class ProtocolDevice(TypingProtocol):
    """What the protocol's loop needs of a device."""

    @property
    def samples(self) -> int:
        """Samples taken so far."""

    def send(self, programme: PulseProgramme) -> None:
        """Start ``programme`` at the device's next sample (or as soon as it can take it);
        the samples :meth:`run` hands back next start with the programme's."""

    def run(self, duration_s: float) -> NDArray[np.float64]:
        """The measured normals (shape (n, 3)) of the next ``duration_s`` of samples (at least
        one)."""


@dataclasses.dataclass(frozen=True)
class ProtocolRecord:
    """What running a protocol did: the samples, each threshold search's bracket as the loop
    decided it while running, and the steps it could not run (with what they need)."""

    samples: int
    brackets: tuple[tuple[str, Bracket], ...]
    not_run: tuple[tuple[str, str], ...]


class _Loop:
    """Probe, rest, observe on one device: the resting normals after the last programme are
    what the next probe is compared with."""

    def __init__(self, device: ProtocolDevice) -> None:
        from sphere_sim.fitting.protocol import REST_S

        self.device = device
        # The first resting stretch: what the first probe is compared with.
        self.resting = device.run(REST_S)

    def send_and_settle(self, programme: PulseProgramme) -> None:
        from sphere_sim.fitting.observations import SETTLE_S
        from sphere_sim.fitting.protocol import REST_S

        self.device.send(programme)
        self.device.run(programme.duration_s + SETTLE_S)
        self.resting = self.device.run(REST_S)

    def search(self, step: ThresholdSearch) -> Bracket:
        from sphere_sim.fitting.protocol import pulled_in

        search = step.bisection()
        while (amplitude := search.next_amplitude()) is not None:
            before = self.resting
            self.send_and_settle(step.probe(amplitude))
            search.observe(pulled_in(before, self.resting))
        return search.bracket

    def kicks(self, step: FrictionKicks) -> None:
        from sphere_sim.kicks.lookup_table import load_kick_model
        from sphere_twin.synthetic_device import kick_programme, kick_sequence, towards_centre

        kicks = load_kick_model()
        for action, intensity, width_s in kick_sequence(kicks, step.n_kicks, step.seed,
                                                        step.intensity_range):
            normal = np.mean(self.resting, axis=0)
            action = towards_centre(kicks, normal / np.linalg.norm(normal), action)
            self.send_and_settle(kick_programme(kicks, action, intensity, width_s))


def run_protocol(device: ProtocolDevice, protocol: Protocol,
                 progress: Callable[[str], object] | None = None,
                 on_bracket: Callable[[str, Bracket], object] | None = None) -> ProtocolRecord:
    """Run ``protocol`` on ``device`` adaptively, after checking it against the voltage limit
    (ProtocolVoltageError before anything is sent).

    ``progress(label)`` is called as each step begins, ``on_bracket(label, bracket)`` as each
    threshold search ends. The kicks are aimed back towards the centre from the mean of the
    resting normals (what the device measures).
    """
    from sphere_sim.fitting.protocol import (
        FrictionKicks,
        SlowRamp,
        ThresholdSearch,
        check_protocol,
        on_wire,
    )

    check_protocol(protocol)
    brackets: list[tuple[str, Bracket]] = []
    not_run: list[tuple[str, str]] = []
    loop = _Loop(device)
    for step in protocol.steps:
        if progress is not None:
            progress(step.label)
        if not on_wire(step):
            not_run.append((step.label, getattr(step, 'measurement', '')))
        elif isinstance(step, ThresholdSearch):
            brackets.append((step.label, loop.search(step)))
            if on_bracket is not None:
                on_bracket(*brackets[-1])
        elif isinstance(step, SlowRamp):
            loop.send_and_settle(step.programme())
        elif isinstance(step, FrictionKicks):
            loop.kicks(step)
    return ProtocolRecord(device.samples, tuple(brackets), tuple(not_run))


class _InProcessDevice:
    """The synthetic device as the protocol's loop sees it (``ProtocolDevice``): programmes
    start at the next sample, the measured normals come back."""

    def __init__(self, recording: DeviceRecording) -> None:
        self.recording = recording

    @property
    def samples(self) -> int:
        return self.recording.samples

    def send(self, programme: PulseProgramme) -> None:
        self.recording.send(programme)

    def run(self, duration_s: float) -> NDArray[np.float64]:
        return self.recording.run(duration_s)[1]


def record_protocol(bag_dir: str | os.PathLike[str], params: ParameterSet | None,
                    protocol: Protocol, seed: int = 0,
                    noise_std_rad: float = NOISE_STUDY_STD_RAD,
                    publish_rate_hz: float = PUBLISH_RATE_HZ,
                    tilt_deg: tuple[float, float] = (0, 0),
                    progress: Callable[[str], object] | None = None) -> ProtocolRecord:
    """Run ``protocol`` on the device ``params`` adaptively and record it into ``bag_dir``.

    Each probe of a threshold search is sent as a programme; when the sphere has settled, the
    resting samples after it are compared with those before it
    (:func:`~sphere_sim.fitting.protocol.pulled_in`) and the search's next amplitude follows
    (:func:`run_protocol`, the loop ``sphere-twin experiment`` runs over the topics). Ramps and
    kicks are sent as they are; a step that needs a measurement the device does not publish is
    skipped and reported. The protocol is checked against the voltage limit before anything is
    sent (ProtocolVoltageError).
    """
    from sphere_sim.fitting.protocol import check_protocol
    from sphere_twin.bag.writer import BagWriter
    from sphere_twin.synthetic_device import DeviceRecording

    check_protocol(protocol)
    with BagWriter(Path(bag_dir)) as bag:
        device = DeviceRecording(bag, params, noise_std_rad, seed, publish_rate_hz, tilt_deg)
        return run_protocol(_InProcessDevice(device), protocol, progress)


def volts_text(value: float | None) -> str:
    return '-' if value is None else f'{value:.2f} V'


def bracket_line(label: str, bracket: Bracket, probes: int | None = None) -> str:
    """One threshold search's bracket, as the recorders print it."""
    below, above = bracket
    return (f'{label}: {volts_text(below)} (not pulled in) to {volts_text(above)} (pulled in)'
            + ('' if probes is None else f', {probes} probes'))


def not_run_line(label: str, needs: str) -> str:
    return f'not run: {label}: needs {needs}, which the device does not publish'


def result_lines(results: ProtocolResults, not_run: tuple[tuple[str, str], ...]) -> list[str]:
    """What a protocol's bag says (``sphere_twin.protocol_bag.read_protocol``) and the steps
    that were not run, one line each, indented under a heading."""
    lines = ['  ' + bracket_line(f'threshold of {b.label}', (b.not_pulled_in_v, b.pulled_in_v),
                                 b.probes) for b in results.brackets]
    for r in results.ramps:
        lines.append(f'  ramp of beams {"+".join(map(str, r.beams))} at {r.rate_v_per_s:g} V/s: '
                     + (f'pulled in between {r.below_v:.2f} and {r.above_v:.2f} V'
                        if r.above_v is not None and r.below_v is not None
                        else 'no pull-in seen'))
    lines += [f'  {not_run_line(label, needs)}' for label, needs in not_run]
    return lines
