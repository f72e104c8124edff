"""The rules a beam command obeys, written once: held voltages and zero-order-hold segments.

The drivers are unipolar and limited (§4.1), a programme's segments start at 0 or later and
increase, and its last segment switches every beam off (it holds for ever). Whoever lets a
command in applies these: a sender before it goes on the wire (:mod:`msg_defs.conversions`),
the twin where a command enters it (:class:`~sphere_sim.twin.runner.TwinRunner`, through
:meth:`~sphere_sim.model.programme.PulseProgramme.from_segments`), and every pulse programme
the model is given (:class:`~sphere_sim.model.programme.PulseProgramme` checks each pulse's
amplitude and what each beam holds between its edges). No ROS here.
"""

import math
from collections.abc import Iterable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from msg_defs.device import BEAM_COUNT, VOLTAGE_LIMIT_V


class VoltageRuleError(ValueError):
    """A beam command that breaks a rule; the message says which."""


def finite_vector(values: ArrayLike, length: int, what: str,
                  error: type[Exception] = ValueError) -> NDArray[np.float64]:
    """``values`` as a float array of shape (length,) of finite numbers, or ``error``."""
    try:
        array = np.asarray(values, dtype=float)
    except (TypeError, ValueError) as exc:
        raise error(f'{what}: not numeric ({exc})') from None
    if array.shape != (length,):
        raise error(f'{what}: expected shape ({length},), got {array.shape}')
    if not np.all(np.isfinite(array)):
        raise error(f'{what}: values must be finite, got {array.tolist()}')
    return array


def check_voltages(voltages_v: ArrayLike, limit_v: float = VOLTAGE_LIMIT_V,
                   what: str = 'voltages') -> NDArray[np.float64]:
    """``voltages_v`` as a float array of shape (BEAM_COUNT,) within [0, limit_v] V."""
    if not (math.isfinite(limit_v) and limit_v > 0):
        raise VoltageRuleError(f'voltage limit must be a positive number, got {limit_v}')
    volts = finite_vector(voltages_v, BEAM_COUNT, what, VoltageRuleError)
    # The electrostatic force goes with V^2, so a negative command is a sign error upstream,
    # not a request.
    if np.any(volts < 0.0):
        raise VoltageRuleError(f'{what}: must be >= 0 V, got {volts.tolist()}')
    worst = float(np.max(volts))
    if worst > limit_v:
        raise VoltageRuleError(f'{what}: |V| = {worst:g} V exceeds the limit {limit_v:g} V')
    return volts


def check_segments(times_s: ArrayLike, voltages_v: Iterable[ArrayLike],
                   limit_v: float = VOLTAGE_LIMIT_V,
                   ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Zero-order-hold segments as arrays ``(times (n,), voltages (n, BEAM_COUNT))``.

    Times are the segments' starts from the programme's start (s): finite, >= 0, strictly
    increasing; each row obeys :func:`check_voltages`; the last row is all 0 V.
    """
    try:
        times = np.asarray(times_s, dtype=float)
    except (TypeError, ValueError) as error:
        raise VoltageRuleError(f'pulse programme times: not numeric ({error})') from None
    if times.ndim != 1 or times.size == 0:
        raise VoltageRuleError(f'pulse programme: expected n >= 1 times, got shape {times.shape}')
    if not np.all(np.isfinite(times)):
        raise VoltageRuleError(f'pulse programme: times must be finite, got {times.tolist()}')
    if times[0] < 0.0:
        raise VoltageRuleError(f'pulse programme: times must be >= 0 s, got {times[0]:g} s')
    if np.any(np.diff(times) <= 0.0):
        raise VoltageRuleError(
            f'pulse programme: times must increase strictly, got {times.tolist()}')
    rows = list(voltages_v)
    if len(rows) != times.size:
        raise VoltageRuleError(
            f'pulse programme: {times.size} times but {len(rows)} voltage rows')
    volts = np.array([check_voltages(row, limit_v, f'pulse programme row {i}')
                      for i, row in enumerate(rows)])
    if np.any(volts[-1] != 0.0):
        raise VoltageRuleError(
            'pulse programme: the last point must switch every beam off (0 V)')
    return times, volts
