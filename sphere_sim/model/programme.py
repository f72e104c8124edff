"""Voltage programmes: rectangular pulses per beam (:class:`PulseProgramme`), and the voltages a
running device holds over time (:class:`VoltageSchedule`); both held constant between edges."""

import dataclasses
import math
from collections.abc import Iterable, Mapping, Sequence
from typing import Any, Literal, Self, get_args

import numpy as np
from numpy.typing import ArrayLike, NDArray

from msg_defs.device import BEAM_IDS, VOLTAGE_LIMIT_V
from msg_defs.voltage_rules import VoltageRuleError, check_segments, check_voltages


class ProgrammeError(ValueError):
    """A pulse programme that cannot be applied to the device."""


# What two pulses on one beam that share time mean: 'refuse' (the default) refuses the
# programme, 'add' sums their amplitudes.
OverlapRule = Literal['refuse', 'add']
OVERLAP_RULES: tuple[OverlapRule, ...] = get_args(OverlapRule)
# A pulse's end is its start plus its width, rounded: one that ends where the next begins may
# end a few units in the last place after it, which is no overlap.
_EDGE_ROUNDING_ULPS = 4


@dataclasses.dataclass(frozen=True)
class Pulse:
    """A rectangular voltage pulse on one beam (beams are numbered 1..4)."""

    beam: int
    amplitude_v: float
    start_s: float
    width_s: float

    @property
    def end_s(self) -> float:
        return self.start_s + self.width_s


@dataclasses.dataclass(frozen=True)
class PulseProgramme:
    """A set of pulses, validated on construction.

    Every pulse's amplitude is >= 0 V (the drivers are unipolar: a negative pulse is refused
    even where a larger one on its beam would hide it in the sum). Two pulses on one beam that
    share time are refused, naming both, unless ``overlap`` is ``'add'``: then the beam holds
    their sum. What a beam holds between any two edges obeys the one rule for held voltages
    (:func:`msg_defs.voltage_rules.check_voltages`: unipolar drivers, at most the limit), as a
    command from the wire does.
    """

    pulses: tuple[Pulse, ...] = ()
    voltage_limit_v: float = VOLTAGE_LIMIT_V
    overlap: OverlapRule = 'refuse'

    def __post_init__(self) -> None:
        object.__setattr__(self, 'pulses', tuple(self.pulses))
        if not (math.isfinite(self.voltage_limit_v) and self.voltage_limit_v > 0):
            raise ProgrammeError(
                f'voltage limit must be a positive number, got {self.voltage_limit_v}')
        if self.overlap not in OVERLAP_RULES:
            raise ProgrammeError(f'overlap must be one of {list(OVERLAP_RULES)}, '
                                 f'got {self.overlap!r}')
        for i, pulse in enumerate(self.pulses):
            self._check_pulse(f'pulse {i} (beam {pulse.beam})', pulse)
        if self.overlap == 'refuse':
            self._refuse_overlaps()
        for t in self.edges():
            try:
                # the sum of overlapping pulses may round a hair above the limit
                check_voltages(self.voltages_at(t), self.voltage_limit_v * (1 + 1e-12),
                               what=f'voltages held from t = {t:g} s')
            except VoltageRuleError as error:
                raise ProgrammeError(str(error)) from None

    def _check_pulse(self, where: str, pulse: Pulse) -> None:
        if pulse.beam not in BEAM_IDS:
            raise ProgrammeError(f'{where}: beam must be one of {BEAM_IDS}')
        for name in ('amplitude_v', 'start_s', 'width_s'):
            if not math.isfinite(getattr(pulse, name)):
                raise ProgrammeError(f'{where}: {name} must be finite, got {getattr(pulse, name)}')
        if pulse.width_s < 0:
            raise ProgrammeError(f'{where}: width_s must be >= 0, got {pulse.width_s}')
        if pulse.start_s < 0:
            raise ProgrammeError(f'{where}: start_s must be >= 0, got {pulse.start_s}')
        if pulse.amplitude_v < 0:
            # Checked pulse by pulse, not only in the sums a beam holds: under 'add' a negative
            # pulse inside a larger one would pass there and cut it silently.
            raise ProgrammeError(f'{where}: amplitude_v must be >= 0 V (the drivers are '
                                 f'unipolar), got {pulse.amplitude_v:g} V')

    def _refuse_overlaps(self) -> None:
        """Refuse two pulses on one beam that share time, naming both: a pulse written over
        another is more often a slip in a start time than a wish for the sum, and the sum would
        hide it. Pulses of zero width hold nothing and overlap nothing."""
        order = sorted((i for i, p in enumerate(self.pulses) if p.width_s > 0),
                       key=lambda i: (self.pulses[i].beam, self.pulses[i].start_s))
        latest: int | None = None  # the pulse on this beam so far that ends last
        for i in order:
            pulse = self.pulses[i]
            if latest is None or self.pulses[latest].beam != pulse.beam:
                latest = i
                continue
            before = self.pulses[latest]
            rounding = _EDGE_ROUNDING_ULPS * math.ulp(before.end_s)
            if pulse.start_s < before.end_s - rounding:
                first, second = sorted((latest, i))
                raise ProgrammeError(
                    f'{_describe(first, self.pulses[first])} and '
                    f'{_describe(second, self.pulses[second])} overlap: move one, or set '
                    'overlap: add to sum them')
            if pulse.end_s > before.end_s:
                latest = i

    @classmethod
    def from_dicts(cls, items: Iterable[Any], voltage_limit_v: float = VOLTAGE_LIMIT_V,
                   overlap: OverlapRule = 'refuse') -> Self:
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
        return cls(tuple(pulses), voltage_limit_v, overlap)

    def edges(self) -> list[float]:
        """Sorted times (s) at which any voltage changes."""
        times = {p.start_s for p in self.pulses} | {p.end_s for p in self.pulses}
        return sorted(times)

    def voltages_at(self, t_s: float, beams: Sequence[int] = BEAM_IDS) -> NDArray[np.float64]:
        """Voltages (V) on ``beams`` at ``t_s``; an edge belongs to the segment after it."""
        out = np.zeros(len(beams))
        for pulse in self.pulses:
            if pulse.beam in beams and pulse.start_s <= t_s < pulse.end_s:
                out[beams.index(pulse.beam)] += pulse.amplitude_v
        return out

    def segments(self, beams: Sequence[int] = BEAM_IDS,
                 ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
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
    def duration_s(self) -> float:
        """End of the last pulse (s)."""
        return max((p.end_s for p in self.pulses), default=0.0)

    @classmethod
    def from_segments(cls, times_s: ArrayLike, voltages_v: Iterable[ArrayLike],
                      voltage_limit_v: float = VOLTAGE_LIMIT_V) -> Self:
        """Inverse of :meth:`segments` for beams 1..4, the device's command rules applied.

        Raises
        ------
        ProgrammeError
            For segments that break :func:`msg_defs.voltage_rules.check_segments`: times not
            finite, negative or strictly increasing, voltages negative or over the limit,
            shapes that do not match, or a last segment that is not zero (it would hold for
            ever).
        """
        try:
            times, volts = check_segments(times_s, voltages_v, voltage_limit_v)
        except VoltageRuleError as error:
            raise ProgrammeError(str(error)) from None
        pulses = [Pulse(beam, float(v), float(t0), float(t1 - t0))
                  for t0, t1, row in zip(times[:-1], times[1:], volts[:-1], strict=True)
                  for beam, v in zip(BEAM_IDS, row, strict=True) if v != 0.0]
        return cls(tuple(pulses), voltage_limit_v)

    def mirrored(self, beam_map: Mapping[int, int]) -> 'PulseProgramme':
        """The same programme with beams renamed by ``beam_map`` (dict old -> new)."""
        return PulseProgramme(tuple(dataclasses.replace(p, beam=beam_map[p.beam])
                                    for p in self.pulses), self.voltage_limit_v, self.overlap)


def _describe(index: int, pulse: Pulse) -> str:
    """A pulse as an error names it: its place in the programme, its beam and its time."""
    return (f'pulse {index} (beam {pulse.beam}, {pulse.amplitude_v:g} V from '
            f'{pulse.start_s:g} to {pulse.end_s:g} s)')


class VoltageSchedule:
    """Piecewise-constant beam voltages over absolute simulated time: what a running device
    holds on its beams.

    A new command replaces whatever the schedule held from its start time on, so the most
    recent command always wins, as on the device's drivers. Like a :class:`PulseProgramme`
    it offers ``edges()`` and ``voltages_at(t_s, beams)``, so the solvers take either.
    """

    def __init__(self) -> None:
        self.times_s: list[float] = [0.0]
        self.voltages_v: list[NDArray[np.float64]] = [np.zeros(len(BEAM_IDS))]

    def replace_from(self, t_s: float, times_s: Iterable[float],
                     voltages_v: Iterable[ArrayLike]) -> None:
        """From ``t_s`` on, the segments ``times_s`` (relative, from 0) and ``voltages_v``."""
        keep = [i for i, t in enumerate(self.times_s) if t < t_s]
        self.times_s = [self.times_s[i] for i in keep] + [t_s + float(t) for t in times_s]
        self.voltages_v = [self.voltages_v[i] for i in keep] + [np.array(v, dtype=float)
                                                                for v in voltages_v]

    def voltages_at(self, t_s: float, beams: Iterable[int] = BEAM_IDS) -> NDArray[np.float64]:
        """Voltages (V) on ``beams`` at ``t_s``; an edge belongs to the segment after it."""
        i = int(np.searchsorted(self.times_s, t_s, side='right')) - 1
        held = self.voltages_v[max(i, 0)]
        return np.array([held[b - 1] for b in beams])

    def edges(self) -> list[float]:
        """Times (s) at which the held voltages change, as :meth:`PulseProgramme.edges`."""
        return list(self.times_s)

    def forget_before(self, t_s: float) -> None:
        """Drop segments that ended before ``t_s`` (the schedule stays short in long runs)."""
        i = int(np.searchsorted(self.times_s, t_s, side='right')) - 1
        if i > 0:
            del self.times_s[:i]
            del self.voltages_v[:i]
