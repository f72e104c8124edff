"""Voltage programmes: rectangular pulses per beam, held constant between edges."""

import dataclasses
import math

import numpy as np

DEFAULT_VOLTAGE_LIMIT_V = 80.0  # hardware limit of the actuators (paper §4.1)


class ProgrammeError(ValueError):
    """A pulse programme that cannot be applied to the device."""


@dataclasses.dataclass(frozen=True)
class Pulse:
    """A rectangular voltage pulse on one beam (beams are numbered 1..4)."""

    beam: int
    amplitude_v: float
    start_s: float
    width_s: float

    @property
    def end_s(self):
        return self.start_s + self.width_s


@dataclasses.dataclass(frozen=True)
class PulseProgramme:
    """A set of pulses, validated on construction.

    Overlapping pulses on the same beam add their amplitudes; the sum must stay within the
    voltage limit too.
    """

    pulses: tuple = ()
    voltage_limit_v: float = DEFAULT_VOLTAGE_LIMIT_V

    def __post_init__(self):
        object.__setattr__(self, 'pulses', tuple(self.pulses))
        if not (math.isfinite(self.voltage_limit_v) and self.voltage_limit_v > 0):
            raise ProgrammeError(
                f'voltage limit must be a positive number, got {self.voltage_limit_v}')
        for i, pulse in enumerate(self.pulses):
            where = f'pulse {i} (beam {pulse.beam})'
            if pulse.beam not in (1, 2, 3, 4):
                raise ProgrammeError(f'{where}: beam must be 1..4')
            for name in ('amplitude_v', 'start_s', 'width_s'):
                if not math.isfinite(getattr(pulse, name)):
                    raise ProgrammeError(
                        f'{where}: {name} must be finite, got {getattr(pulse, name)}')
            if pulse.width_s < 0:
                raise ProgrammeError(f'{where}: width_s must be >= 0, got {pulse.width_s}')
            if pulse.start_s < 0:
                raise ProgrammeError(f'{where}: start_s must be >= 0, got {pulse.start_s}')
            if abs(pulse.amplitude_v) > self.voltage_limit_v:
                raise ProgrammeError(
                    f'{where}: |amplitude_v| = {abs(pulse.amplitude_v)} V exceeds the limit '
                    f'{self.voltage_limit_v} V')
        for t in self.edges():
            peak = np.max(np.abs(self.voltages_at(t, beams=(1, 2, 3, 4))))
            if peak > self.voltage_limit_v * (1 + 1e-12):
                raise ProgrammeError(f'overlapping pulses reach {peak} V at t = {t} s, '
                                     f'above {self.voltage_limit_v} V')

    @classmethod
    def from_dicts(cls, items, voltage_limit_v=DEFAULT_VOLTAGE_LIMIT_V):
        pulses = []
        for i, item in enumerate(items):
            allowed = {f.name for f in dataclasses.fields(Pulse)}
            if not isinstance(item, dict) or set(item) != allowed:
                raise ProgrammeError(f'pulse {i} must have exactly the keys {sorted(allowed)}, '
                                     f'got {item!r}')
            try:
                pulses.append(Pulse(beam=int(item['beam']), amplitude_v=float(item['amplitude_v']),
                                    start_s=float(item['start_s']), width_s=float(item['width_s'])))
            except (TypeError, ValueError) as exc:
                raise ProgrammeError(f'pulse {i}: {exc}') from exc
        return cls(tuple(pulses), voltage_limit_v)

    def edges(self):
        """Sorted times (s) at which any voltage changes."""
        times = {p.start_s for p in self.pulses} | {p.end_s for p in self.pulses}
        return sorted(times)

    def voltages_at(self, t_s, beams=(1, 2, 3, 4)):
        """Voltages (V) on ``beams`` at ``t_s``; an edge belongs to the segment after it."""
        out = np.zeros(len(beams))
        for pulse in self.pulses:
            if pulse.beam in beams and pulse.start_s <= t_s < pulse.end_s:
                out[beams.index(pulse.beam)] += pulse.amplitude_v
        return out

    def segments(self, beams=(1, 2, 3, 4)):
        """The programme as zero-order-hold segments.

        Returns
        -------
        times_s : ndarray, shape (n,)
            Start of each segment, from 0, increasing; the last segment (all pulses over)
            lasts for ever.
        voltages_v : ndarray, shape (n, len(beams))
        """
        times = sorted({0.0, *self.edges()})
        return np.array(times), np.array([self.voltages_at(t, beams) for t in times])

    @property
    def duration_s(self):
        """End of the last pulse (s)."""
        return max((p.end_s for p in self.pulses), default=0.0)

    @classmethod
    def from_segments(cls, times_s, voltages_v, voltage_limit_v=DEFAULT_VOLTAGE_LIMIT_V):
        """Inverse of :meth:`segments` for beams 1..4; the last segment must be all zero.

        Raises
        ------
        ProgrammeError
            For times that are not finite, negative or strictly increasing, shapes that do
            not match, or a last segment that is not zero (it would hold for ever).
        """
        times = np.asarray(times_s, dtype=float)
        volts = np.asarray(voltages_v, dtype=float)
        if times.ndim != 1 or volts.shape != (times.size, 4):
            raise ProgrammeError(f'expected n times and n x 4 voltages, got shapes '
                                 f'{times.shape} and {volts.shape}')
        if not (np.all(np.isfinite(times)) and np.all(np.isfinite(volts))):
            raise ProgrammeError('times and voltages must be finite')
        if times.size and times[0] < 0.0:
            raise ProgrammeError(f'times must be >= 0, got {times[0]} s')
        if np.any(np.diff(times) <= 0.0):
            raise ProgrammeError(f'times must increase strictly, got {times.tolist()}')
        if times.size and np.any(volts[-1] != 0.0):
            raise ProgrammeError('the last segment must switch every beam off (0 V)')
        pulses = [Pulse(beam, float(v), float(t0), float(t1 - t0))
                  for t0, t1, row in zip(times[:-1], times[1:], volts[:-1], strict=True)
                  for beam, v in zip((1, 2, 3, 4), row, strict=True) if v != 0.0]
        return cls(tuple(pulses), voltage_limit_v)

    def mirrored(self, beam_map):
        """The same programme with beams renamed by ``beam_map`` (dict old -> new)."""
        return PulseProgramme(tuple(dataclasses.replace(p, beam=beam_map[p.beam])
                                    for p in self.pulses), self.voltage_limit_v)
