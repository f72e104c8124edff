"""An experiment protocol a hardware user can run: pull-in thresholds found by bisection,
slow ramps, and kicks for the friction, as pulse programmes and the normal sensor's samples.

Kicks alone hardly tell the pull-in's parameters apart on the paper's device: a kick's landing
moves in steps as they change, while a *threshold* moves smoothly with them
(docs/identification.md, "An experiment protocol"). The protocol therefore asks the device
where its beams pull in, one beam or one pair at a time, at several pulse widths (a short
pulse's threshold is dynamic: the beams' inertia and damping; a slow ramp's is static: the
stiffness and the gap), and only then kicks it for the friction.

Everything here is data and logic: no ROS, no I/O. A step is a frozen dataclass; a threshold
search is run by :class:`Bisection` (``next_amplitude()`` / ``observe(pulled_in)``), which a
recorder drives with what the device has, the beams' voltages and the sensor's resting
normals. Reading a recording back (:func:`probe_brackets`, :func:`ramp_pull_in`) classifies
each programme by its shape, so the recording needs nothing beside the device's own topics.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from collections.abc import Iterable, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from msg_defs.device import BEAM_IDS, VOLTAGE_LIMIT_V
from sphere_sim.fitting.observations import SETTLE_S, KickObservation, Observations
from sphere_sim.model.programme import PulseProgramme

# A probe is a train of identical pulses, each after the last one's kick has ended: one pulled-in
# pulse moves the resting normal by only 2.0e-4 to 4.3e-4 rad on the paper's device, a fifth to
# a half of the sensor noise of one sample (the noise study's 9.4e-4 rad per axis), while the
# pulses of a train move it the same way, each by as much as the one before (measured on
# `calibrated`, beam 3, 5 ms: 10 pulses at 46 V move it 2.1e-4 rad, at 47 V 2.1e-3 rad).
PROBE_PULSES = 10
PROBE_SPACING_S = 0.1  # past the 60 ms kick window, so each pulse starts from rest
# Largest movement per pulse counted as "not pulled in". Measured on `calibrated` from level
# (`assemble(load_scene('rest'))`, the normal 0.1 s after one pulse): below pull-in a pulse moves
# the sphere by at most 2.2e-5 rad (beam 3, 5 ms, 46 V), 1.7e-5 (beams 3+4, 5 ms, 42 V) and
# 5.1e-5 (beam 3, 1.5 ms, 55 V), all growing towards the threshold; a pulled-in pulse moves it by
# at least 2.0e-4 (beams 3+4, 44 V), 2.1e-4 (beam 3, 47 V) and 4.3e-4 (beam 3, 1.5 ms, 60 V). The
# floor sits near the geometric middle of 5.1e-5 and 2.0e-4, a factor of two from either.
PULL_IN_STEP_RAD = 1e-4
# Sigmas of the difference of the two resting means (per axis) a pulled-in probe must exceed:
# the difference's length is Rayleigh-distributed under noise alone, exceeding k sigma with
# probability exp(-k^2 / 2), 3.4e-4 for k = 4: one false "pulled in" in some 3000 probes.
NOISE_SIGMAS = 4.0
# Resting samples averaged before and after a probe; with 10 pulses and the noise study's
# sensor, the noise term (4 x 9.4e-4 x sqrt(2 / 60) = 6.9e-4 rad) stays below the floor
# (10 x 1e-4), so the floor decides and the noise adds a false call rarely.
REST_S = 0.6

# A slow ramp's staircase: steps this small (V) at the ramp's rate; the jump of the normal at
# pull-in is read from windows of this many samples on either side (at 100 Hz and 20 V/s:
# 2 V of ramp, over which the normal's smooth drift, 6e-5 rad/V below pull-in on `calibrated`,
# stays a tenth of the jump).
RAMP_STEP_V = 0.1
RAMP_WINDOW_SAMPLES = 10
# Measured on `calibrated`, beam 3 ramped at 50 V/s: held just below pull-in (46 V) the normal
# stands 1.3e-3 rad off its rest, held pulled in (48 V) 4.2e-3: a jump of 2.9e-3 rad, three
# times one sample's noise and ten times that of a window's mean.
RAMP_JUMP_RAD = 1.5e-3

# What the beams alone (no sphere placed) would need: the normal sensor sees the sphere, so a
# bare beam's pull-in shows only in its capacitance, which the device does not publish.
ACTUATOR_CAPACITANCE = "the actuators' capacitance"


class ProtocolError(ValueError):
    """A protocol that cannot be run as given."""


class ProtocolVoltageError(ProtocolError):
    """A protocol step that could command more than the device's voltage limit."""


def _beams_text(beams: Sequence[int]) -> str:
    return ('beam ' if len(beams) == 1 else 'beams ') + '+'.join(str(b) for b in beams)


@dataclasses.dataclass(frozen=True)
class ThresholdSearch:
    """Bisection on the amplitude of a probe: :data:`PROBE_PULSES` pulses of ``width_s`` on
    ``beams`` (at once), with the sphere on; pulled in or not from the resting normals."""

    beams: tuple[int, ...]
    width_s: float
    bracket_v: tuple[float, float]
    resolution_v: float = 0.2

    @property
    def label(self) -> str:
        return f'threshold of {_beams_text(self.beams)}, {self.width_s * 1e3:g} ms pulses'

    @property
    def peak_v(self) -> float:
        return self.bracket_v[1]

    def probe(self, amplitude_v: float) -> PulseProgramme:
        return probe_programme(self.beams, self.width_s, amplitude_v)

    def bisection(self) -> Bisection:
        return Bisection(*self.bracket_v, self.resolution_v)


@dataclasses.dataclass(frozen=True)
class SlowRamp:
    """A staircase from ``start_v`` to ``peak_v`` at ``rate_v_per_s`` on ``beams``, then off:
    the static pull-in shows as a jump of the normal during the ramp (:func:`ramp_pull_in`)."""

    beams: tuple[int, ...]
    rate_v_per_s: float
    start_v: float
    peak_v: float

    @property
    def label(self) -> str:
        return (f'ramp of {_beams_text(self.beams)}, {self.start_v:g} to {self.peak_v:g} V '
                f'at {self.rate_v_per_s:g} V/s')

    def programme(self) -> PulseProgramme:
        return ramp_programme(self.beams, self.rate_v_per_s, self.start_v, self.peak_v)


@dataclasses.dataclass(frozen=True)
class BeamsOnlyThreshold:
    """A threshold of the beams before the sphere is placed. The normal sensor has nothing to
    see then: the step needs ``measurement``, which is not on the device's wire, so a recorder
    of the device's topics reports it as not runnable."""

    beams: tuple[int, ...]
    width_s: float
    bracket_v: tuple[float, float]
    measurement: str = ACTUATOR_CAPACITANCE

    @property
    def label(self) -> str:
        return (f'threshold of {_beams_text(self.beams)} without the sphere, '
                f'{self.width_s * 1e3:g} ms pulses')

    @property
    def peak_v(self) -> float:
        return self.bracket_v[1]


@dataclasses.dataclass(frozen=True)
class FrictionKicks:
    """Kicks of the shipped table for the friction, once the thresholds are known: described
    by count, seed and intensities; the recorder builds them (the kick sequence lives with the
    recorders, above this library)."""

    n_kicks: int = 20
    seed: int = 0
    intensity_range: tuple[float, float] = (0.8, 1.0)

    @property
    def label(self) -> str:
        return (f'{self.n_kicks} kicks at intensities {self.intensity_range[0]:g} to '
                f'{self.intensity_range[1]:g}')


Step = ThresholdSearch | SlowRamp | BeamsOnlyThreshold | FrictionKicks


def on_wire(step: Step) -> bool:
    """Whether the step needs only the device's wire (programmes out, the normal in)."""
    return not isinstance(step, BeamsOnlyThreshold)


@dataclasses.dataclass(frozen=True)
class Protocol:
    steps: tuple[Step, ...]

    def not_on_wire(self) -> list[tuple[Step, str]]:
        """The steps that need a measurement the device does not publish, with it."""
        return [(s, s.measurement) for s in self.steps if isinstance(s, BeamsOnlyThreshold)]


def check_protocol(protocol: Protocol, voltage_limit_v: float = VOLTAGE_LIMIT_V) -> None:
    """Refuse, before anything is sent, a protocol any step of which could command more than
    ``voltage_limit_v`` (or less than 0 V, or a beam the device lacks).

    Raises
    ------
    ProtocolVoltageError
        One line naming the step and the limit.
    """
    for i, step in enumerate(protocol.steps, 1):
        if isinstance(step, FrictionKicks):
            low, high = step.intensity_range
            if not 0.0 <= low <= high <= 1.0:
                raise ProtocolError(f'step {i} ({step.label}): intensities must lie in '
                                    f'[0, 1]')
            continue  # the kick table's designs keep to the limit (KickDesign.programme)
        if any(b not in BEAM_IDS for b in step.beams) or not step.beams:
            raise ProtocolError(f'step {i} ({step.label}): beams must be some of {BEAM_IDS}')
        lowest = step.start_v if isinstance(step, SlowRamp) else step.bracket_v[0]
        if step.peak_v > voltage_limit_v or lowest < 0.0 or not math.isfinite(step.peak_v):
            raise ProtocolVoltageError(
                f'step {i} ({step.label}) could command {step.peak_v:g} V (from {lowest:g}): '
                f'the limit is 0 to {voltage_limit_v:g} V')


class Bisection:
    """The threshold search as a state machine: ask :meth:`next_amplitude`, probe the device
    at it, tell :meth:`observe` whether it pulled in; until the bracket is narrower than the
    resolution (then :meth:`next_amplitude` returns None).

    The bracket's ends are not probed first: a pulled-in probe at the top of the bracket would
    cost a probe and move the sphere for nothing. :attr:`bracket` reports only what was seen,
    with None for a side never seen (the threshold lies outside the bracket on that side).
    """

    def __init__(self, low_v: float, high_v: float, resolution_v: float) -> None:
        if not (0.0 <= low_v < high_v and resolution_v > 0.0):
            raise ProtocolError(f'bisection needs 0 <= low < high and a resolution > 0, got '
                                f'{low_v}, {high_v}, {resolution_v}')
        self._low, self._high, self.resolution_v = low_v, high_v, resolution_v
        self.not_pulled_in_v: float | None = None
        self.pulled_in_v: float | None = None
        self.history: list[tuple[float, bool]] = []
        self._asked: float | None = None

    @property
    def bracket(self) -> tuple[float | None, float | None]:
        """(highest amplitude seen not to pull in, lowest seen to pull in)."""
        return self.not_pulled_in_v, self.pulled_in_v

    def next_amplitude(self) -> float | None:
        if self._high - self._low <= self.resolution_v:
            return None
        self._asked = 0.5 * (self._low + self._high)
        return self._asked

    def observe(self, pulled_in: bool) -> None:
        if self._asked is None:
            raise ProtocolError('observe() before next_amplitude()')
        amplitude, self._asked = self._asked, None
        self.history.append((amplitude, pulled_in))
        if pulled_in:
            self._high = amplitude
            self.pulled_in_v = amplitude
        else:
            self._low = amplitude
            self.not_pulled_in_v = amplitude


def probe_programme(beams: Sequence[int], width_s: float, amplitude_v: float,
                    pulses: int = PROBE_PULSES,
                    spacing_s: float = PROBE_SPACING_S) -> PulseProgramme:
    """``pulses`` pulses of ``amplitude_v`` and ``width_s`` on ``beams`` at once, one every
    ``spacing_s``."""
    times, volts = [], []
    for i in range(pulses):
        times += [i * spacing_s, i * spacing_s + width_s]
        volts += [[amplitude_v if b in beams else 0.0 for b in BEAM_IDS], [0.0] * len(BEAM_IDS)]
    return PulseProgramme.from_segments(times, volts)


def ramp_programme(beams: Sequence[int], rate_v_per_s: float, start_v: float,
                   peak_v: float, step_v: float = RAMP_STEP_V) -> PulseProgramme:
    """A staircase of ``step_v`` steps from ``start_v`` to ``peak_v`` at ``rate_v_per_s``, the
    beams switched off at its end (zero-order-hold segments, as the wire carries them)."""
    steps = max(1, round((peak_v - start_v) / step_v))
    dwell = (peak_v - start_v) / steps / rate_v_per_s
    levels = [start_v + (peak_v - start_v) * i / steps for i in range(steps + 1)]
    times = [i * dwell for i in range(steps + 2)]
    volts = [[v if b in beams else 0.0 for b in BEAM_IDS] for v in levels]
    return PulseProgramme.from_segments(times, [*volts, [0.0] * len(BEAM_IDS)])


def detection_threshold_rad(noise_std_rad: float, samples_before: int, samples_after: int,
                            pulses: int = PROBE_PULSES) -> float:
    """How far the resting normal must move for a probe to count as pulled in: past the noise
    of the two means (:data:`NOISE_SIGMAS`) and past what sub-threshold pulses move it
    (:data:`PULL_IN_STEP_RAD` each)."""
    noise = NOISE_SIGMAS * noise_std_rad * math.sqrt(1.0 / samples_before + 1.0 / samples_after)
    return max(noise, pulses * PULL_IN_STEP_RAD)


def _unit_mean(normals: NDArray[np.float64]) -> NDArray[np.float64]:
    mean = np.mean(normals, axis=0)
    return np.asarray(mean / np.linalg.norm(mean))


def tangential_noise_rad(*stretches: ArrayLike) -> float:
    """Per-axis noise (rad) from the scatter of resting stretches about their own means."""
    ss, dof = 0.0, 0
    for stretch in stretches:
        n = np.asarray(stretch, dtype=float)
        if len(n) < 2:
            continue
        mean = _unit_mean(n)
        d = n - mean
        d -= np.outer(d @ mean, mean)
        ss, dof = ss + float(np.sum(d * d)), dof + 2 * (len(n) - 1)
    return math.sqrt(ss / dof) if dof else 0.0


def moved_rad(normal_before: ArrayLike, normal_after: ArrayLike) -> float:
    a, b = np.asarray(normal_before, dtype=float), np.asarray(normal_after, dtype=float)
    return math.atan2(float(np.linalg.norm(np.cross(a, b))), float(a @ b))


def pulled_in(before: ArrayLike, after: ArrayLike, pulses: int = PROBE_PULSES) -> bool:
    """The detection rule on the resting samples (shape (n, 3)) before and after a probe, the
    noise measured from their own scatter: what a recorder decides with while it runs."""
    b, a = np.asarray(before, dtype=float), np.asarray(after, dtype=float)
    threshold = detection_threshold_rad(tangential_noise_rad(b, a), len(b), len(a), pulses)
    return moved_rad(_unit_mean(b), _unit_mean(a)) > threshold


@dataclasses.dataclass(frozen=True)
class Probe:
    """A recorded programme read as a probe: identical pulses on ``beams`` at once."""

    beams: tuple[int, ...]
    width_s: float
    amplitude_v: float
    pulses: int


def probe_of(times_s: ArrayLike, voltages_v: ArrayLike) -> Probe | None:
    """The probe a programme's segments are, or None (a ramp, a kick, anything else): every
    powered segment holds one amplitude on the same beams, all of one width."""
    times = np.asarray(times_s, dtype=float)
    volts = np.asarray(voltages_v, dtype=float)
    powered = [i for i in range(len(times) - 1) if np.any(volts[i] > 0)]
    if not powered:
        return None
    rows = volts[powered]
    beams = tuple(int(b) for b in np.flatnonzero(rows[0] > 0) + 1)
    amplitude = float(rows[0][beams[0] - 1])
    expected = np.array([amplitude if b in beams else 0.0 for b in BEAM_IDS])
    widths = times[[i + 1 for i in powered]] - times[powered]
    if not (np.allclose(rows, expected) and np.allclose(widths, widths[0], rtol=1e-6)):
        return None
    # Pulses are separated by unpowered segments; adjacent powered segments would be a ramp.
    if any(b - a == 1 for a, b in itertools.pairwise(powered)):
        return None
    return Probe(beams, round(float(widths[0]), 9), amplitude, len(powered))


def resting_around(t_s: ArrayLike, normals: ArrayLike,
                   programmes: Iterable[tuple[float, ArrayLike, ArrayLike]],
                   settle_s: float = SETTLE_S) -> tuple[list[KickObservation], float]:
    """Each recorded programme with the resting normals around it, cut as the recorder waits:
    from ``settle_s`` after a programme's last edge (a probe's last pulse, not its start) to the
    next programme. Returns the observations (programmes without two samples on either side
    left out) and the per-axis noise from the scatter of the resting stretches."""
    t = np.asarray(t_s, dtype=float)
    n = np.asarray(normals, dtype=float)
    progs = sorted(((float(s), np.asarray(ts, dtype=float), np.asarray(vs, dtype=float))
                    for s, ts, vs in programmes), key=lambda p: p[0])
    out: list[KickObservation] = []
    stretches = []
    for i, (start, times, volts) in enumerate(progs):
        rested = progs[i - 1][0] + progs[i - 1][1][-1] + settle_s if i else -math.inf
        settled = start + times[-1] + settle_s
        following = progs[i + 1][0] if i + 1 < len(progs) else math.inf
        before = (t >= rested - 1e-9) & (t < start - 1e-9)
        after = (t >= settled - 1e-9) & (t < following - 1e-9)
        if before.sum() < 2 or after.sum() < 2:
            continue
        if not out:
            stretches.append(n[before])
        stretches.append(n[after])
        out.append(KickObservation(start, times, volts, _unit_mean(n[before]),
                                   _unit_mean(n[after]), int(before.sum()), int(after.sum())))
    return out, tangential_noise_rad(*stretches)


@dataclasses.dataclass(frozen=True)
class ProbeBracket:
    """What the probes of one step (same beams, same width) say of its threshold."""

    beams: tuple[int, ...]
    width_s: float
    not_pulled_in_v: float | None  # highest amplitude that did not pull in
    pulled_in_v: float | None  # lowest that did
    probes: int
    # Where the sphere rested before the bracket's end probes (the unit mean of the resting
    # normals before each, one if only one side was seen): a pulled-in probe moves it by some
    # 2e-3 rad, so a search drifts and a model of the threshold must start from here.
    normal_before: tuple[float, float, float] | None = None

    @property
    def label(self) -> str:
        return f'{_beams_text(self.beams)}, {self.width_s * 1e3:g} ms'

    def contains(self, threshold_v: float) -> bool:
        low = -math.inf if self.not_pulled_in_v is None else self.not_pulled_in_v
        high = math.inf if self.pulled_in_v is None else self.pulled_in_v
        return low < threshold_v <= high


def probe_brackets(kicks: Iterable[KickObservation],
                   noise_std_rad: float) -> list[ProbeBracket]:
    """Group the recorded probes by step (beams and width) and read each step's bracket from
    the resting normals around its probes (:func:`detection_threshold_rad` with the recording's
    noise). Kicks and ramps are not probes and are passed over."""
    seen: dict[tuple[tuple[int, ...], float],
               list[tuple[float, bool, NDArray[np.float64]]]] = {}
    for kick in kicks:
        probe = probe_of(kick.times_s, kick.voltages_v)
        if probe is None:
            continue
        threshold = detection_threshold_rad(noise_std_rad, kick.samples_before,
                                            kick.samples_after, probe.pulses)
        moved = moved_rad(kick.normal_before, kick.normal_after)
        seen.setdefault((probe.beams, probe.width_s), []).append(
            (probe.amplitude_v, moved > threshold, np.asarray(kick.normal_before, dtype=float)))
    out = []
    for (beams, width), looks in seen.items():
        below = max((look for look in looks if not look[1]), key=lambda look: look[0],
                    default=None)
        above = min((look for look in looks if look[1]), key=lambda look: look[0],
                    default=None)
        ends = [look[2] for look in (below, above) if look is not None]
        normal = _unit_mean(np.array(ends))
        out.append(ProbeBracket(beams, width, below[0] if below else None,
                                above[0] if above else None, len(looks),
                                (float(normal[0]), float(normal[1]), float(normal[2]))))
    return out


@dataclasses.dataclass(frozen=True)
class RampPullIn:
    """Where a slow ramp pulled in: the voltages held at the samples either side of the jump,
    and those samples' times after the ramp's start (None: no jump above
    :data:`RAMP_JUMP_RAD`)."""

    beams: tuple[int, ...]
    rate_v_per_s: float
    below_v: float | None
    above_v: float | None
    jump_rad: float
    below_s: float | None = None
    above_s: float | None = None


def ramp_of(times_s: ArrayLike, voltages_v: ArrayLike) -> tuple[tuple[int, ...], float] | None:
    """(beams, rate in V/s) of a programme that is a rising staircase, or None."""
    times = np.asarray(times_s, dtype=float)
    volts = np.asarray(voltages_v, dtype=float)
    if len(times) < 4:
        return None
    powered = volts[:-1]
    beams = tuple(int(b) for b in np.flatnonzero(powered[-1] > 0) + 1)
    level = powered[:, beams[0] - 1] if beams else np.zeros(0)
    if not beams or np.any(np.diff(level) <= 0):
        return None
    rate = float((level[-1] - level[0]) / (times[-2] - times[0]))
    return beams, rate


def ramp_pull_in(t_s: ArrayLike, normals: ArrayLike, start_s: float, times_s: ArrayLike,
                 voltages_v: ArrayLike,
                 window: int = RAMP_WINDOW_SAMPLES) -> RampPullIn | None:
    """The jump of the normal during a recorded ramp (samples ``t_s``, ``normals``; the ramp
    starts at ``start_s`` with segments ``times_s``, ``voltages_v``): the sample where the
    means of ``window`` samples after and before differ most. None if the programme is no
    ramp."""
    shape = ramp_of(times_s, voltages_v)
    if shape is None:
        return None
    beams, rate = shape
    times = np.asarray(times_s, dtype=float)
    volts = np.asarray(voltages_v, dtype=float)
    t = np.asarray(t_s, dtype=float)
    n = np.asarray(normals, dtype=float)
    inside = np.flatnonzero((t >= start_s) & (t < start_s + times[-1]))
    best, at = 0.0, -1
    for j in range(window, len(inside) - window + 1):
        before = _unit_mean(n[inside[j - window:j]])
        after = _unit_mean(n[inside[j:j + window]])
        jump = moved_rad(before, after)
        if jump > best:
            best, at = jump, j
    if at < 0 or best < RAMP_JUMP_RAD:
        return RampPullIn(beams, rate, None, None, best)

    def held(sample: int) -> float:
        k = int(np.searchsorted(times, t[sample] - start_s, side='right')) - 1
        return float(volts[max(k, 0), beams[0] - 1])

    return RampPullIn(beams, rate, held(inside[at - 1]), held(inside[at]), best,
                      float(t[inside[at - 1]] - start_s), float(t[inside[at]] - start_s))


# The paper's device (`calibrated`): the four beams alone and the two pairs its kicks drive
# together (KickDesign: beams 1+2 low, 3+4 high; an opposite pair lifts the sphere straight and
# it lands where it was, 2.6e-5 rad at 60 V for beams 1+3, so the sensor cannot see it pull in),
# at the paper's 5 ms (Fig. 4) and a short 1.5 ms; thresholds on `calibrated`: beam 3 46-47 V
# at 5 ms and 55-60 V at 1.5 ms, beams 3+4 42-44 V at 5 ms. Ramps on the single beams at
# 20 V/s (quasi-static: the beams' own time is milliseconds; beam 3 pulls in at 46-48 V).
PROBE_BEAMS: tuple[tuple[int, ...], ...] = ((1,), (2,), (3,), (4,), (1, 2), (3, 4))
PROBE_WIDTHS_S = (1.5e-3, 5e-3)
BRACKETS_V = {1.5e-3: (30.0, 78.0), 5e-3: (25.0, 70.0)}
SEARCH_RESOLUTION_V = 0.2
# The golden ratio's fractional part: i times it, modulo 1, spreads any number of searches
# evenly over [0, 1) (a low-discrepancy sequence, the same every run).
GOLDEN_FRACTION = (math.sqrt(5.0) - 1.0) / 2.0


def last_bracket_width_v(bracket_v: tuple[float, float], resolution_v: float) -> float:
    """The width of the last bracket a bisection of ``bracket_v`` to ``resolution_v`` ends in."""
    low, high = bracket_v
    halvings = max(0, math.ceil(math.log2((high - low) / resolution_v)))
    return (high - low) / 2.0 ** halvings


def dithered(bracket_v: tuple[float, float], resolution_v: float,
             search: int) -> tuple[float, float]:
    """``bracket_v`` shifted by the ``search``-th golden-ratio fraction of its last bracket's
    width.

    A bisection of one bracket always probes the same amplitudes, so searches of thresholds
    that lie close together end in the same last bracket: the four beams of a symmetric device
    did (noiseless paper_b, beams 1-4 at 5 ms, all in 44.16-44.34 V, the model's threshold
    0.08 V below the middle for each). Their residuals' quantisation is then one draw shared
    four times, which a fit counting them as four independent ones reads as twice the
    precision it has. Shifted each by its own fraction, the searches' grids interleave: their
    quantisation errors are independent, and together they resolve the threshold finer than one.
    """
    shift = (search * GOLDEN_FRACTION) % 1.0 * last_bracket_width_v(bracket_v, resolution_v)
    return bracket_v[0] + shift, bracket_v[1] + shift


DEFAULT_PROTOCOL = Protocol((
    *(ThresholdSearch(beams, width, dithered(BRACKETS_V[width], SEARCH_RESOLUTION_V, i),
                      SEARCH_RESOLUTION_V)
      for i, (width, beams) in enumerate(itertools.product(PROBE_WIDTHS_S, PROBE_BEAMS))),
    *(SlowRamp((beam,), 20.0, 30.0, 65.0) for beam in BEAM_IDS),
    BeamsOnlyThreshold((1, 2, 3, 4), 5e-3, (20.0, 70.0)),
    FrictionKicks(20, 0, (0.8, 1.0)),
))


def friction_kicks(observations: Observations) -> Observations:
    """The kicks among a recording's programmes: the observations less the protocol's probes
    and ramps, whose resting normals tell thresholds, not landings (a probe's ten pulses and a
    ramp's staircase would be read as kicks the model has not been asked for)."""
    return observations.without(
        i for i, kick in enumerate(observations.kicks)
        if probe_of(kick.times_s, kick.voltages_v) is not None
        or ramp_of(kick.times_s, kick.voltages_v) is not None)


# Which of the protocol's experiments determines a parameter, by its section (the protocol's
# table, docs/identification.md): the threshold searches the beams' stiffness, gap and damping
# (where they pull in), the kicks the contact's friction (where a kick lands once the beams are
# pinned).
THRESHOLD_SECTIONS = ('beam', 'electrostatics')
KICK_SECTIONS = ('friction', 'contact', 'sphere')


def missing_experiment(path: str, thresholds: bool, kicks: bool) -> str | None:
    """The experiment that determines the parameter ``path`` if the recordings lack it (they
    hold ``thresholds`` searches, ``kicks``), else None."""
    section = path.split('.', 1)[0]
    if section in THRESHOLD_SECTIONS and not thresholds:
        return "the protocol's threshold searches"
    if section in KICK_SECTIONS and not kicks:
        return 'kicks'
    return None
