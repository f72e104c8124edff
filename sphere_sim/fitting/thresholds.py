"""The model side of the protocol's threshold searches: the pull-in threshold of a probe step
for a parameter set, and a recorded bracket as a residual.

A threshold search (:mod:`sphere_sim.fitting.protocol`) brackets the amplitude at which a
probe of ``beams`` and ``width_s`` pulls in, from the sphere resting where the recording says
it rested. The model's threshold is found on direct simulation, on a fixed lattice of
amplitudes (:data:`MODEL_RESOLUTION_V`), with the rule the protocol's floor encodes: one pulse,
started at rest at the recorded normal, has pulled in when the resting normal
:data:`~sphere_sim.fitting.protocol.PROBE_SPACING_S` after its start (when the train's next
pulse would begin) lies more than :data:`~sphere_sim.fitting.protocol.PULL_IN_STEP_RAD` from
the normal before it.

Unlike a kick's landing, which moves in steps as the beams' parameters change, a threshold moves
smoothly with them (docs/identification.md, "An experiment protocol"); its misfit has only the
lattice's resolution as steps, where the pulses' outcome rises once with the amplitude. Where it
does not (paper_b's pairs at 1.5 ms), the recorded bracket is whichever switch the device's
bisection met; such an observation is found by a scan before a fit (:func:`non_monotone`) and
left out.

Cost, measured on one core (`calibrated` and paper_b's twelve brackets, each from its recorded
rest): the rest state 0.1 s, one pulse 0.05 s (not pulled in) to 0.1 s (pulled in). All twelve
at paper_b's truth, 7.6 s (70 pulses) searched from the recorded brackets' middles, 3.4 s (24
pulses) from the right cells, 4.6 s (36) from 0.013 V above them, 15 s (156) from 0.5 V above
them, each galloping from a step of one cell. A fit predicts each search's cell from the
thresholds of the points it searched before (:func:`predicted_thresholds_v`).
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import time
from collections import OrderedDict
from collections.abc import Iterable, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray
from threadpoolctl import threadpool_limits

from msg_defs.device import VOLTAGE_LIMIT_V
from sphere_sim.fitting.protocol import (
    PROBE_SPACING_S,
    PULL_IN_STEP_RAD,
    ProbeBracket,
    moved_rad,
    probe_programme,
)
from sphere_sim.integrate.tolerances import FIT_RTOL
from sphere_sim.kicks.design import KICK_RELAXATION, cardan_of_normal, final_normal
from sphere_sim.kicks.engine import SerialEngine
from sphere_sim.kicks.process_models import process_model
from sphere_sim.kicks.table_build import BLAS_THREADS_PER_KICK
from sphere_sim.model.initial_state import rest_state
from sphere_sim.model.parameters import ParameterSet

# The model's threshold is the cell of this width (V) it lies in, on a lattice from a fixed origin
# (in a fit, the recorded bracket's low end), reported at the cell's middle: a twentieth of the
# protocol's 0.2 V resolution. Its quantisation (uniform,
# within +-0.005 V) moves a residual by at most a tenth of a bracket's standard deviation
# (0.052 V), so that the misfit's steps stay well below the rise of 3.84 an interval is read at;
# each halving costs one more pulse.
MODEL_RESOLUTION_V = 0.01
# The model's own error in a threshold (V, one standard deviation): one pulse from rest at the
# resting normal stands in for a train of ten from the sphere as the search left it. Measured at
# the truth on recordings of the default protocol on paper_a to paper_e, 60 brackets each: the
# model's threshold lies inside the recorded bracket for 55 of the noiseless ones, and the
# residuals' spread exceeds what the brackets' widths explain by 0.051 V (noiseless) and 0.045 V
# (the noise study's sensor), nearly all of it paper_d's single beams at 5 ms (0.09 to 0.26 V
# off, with k_phi x 0.75 and d_B,phi x 1.3). Without it (and with the searches undithered) the
# four single beams of one width counted as four observations of a threshold they all missed
# alike, and the intervals narrowed past the truth (paper_b, all twelve brackets:
# docs/identification.md).
MODEL_ERROR_V = 0.05
# Thresholds kept per process (each is some 0.3-1.7 s of simulation): a fit's multi-start and its
# profiles come back to points they evaluated.
CACHE_SIZE = 4096
# Neighbours per fitted parameter that a threshold's prediction is fitted to (an affine fit needs
# n + 1): twice that, so that one point from across a kink or a sheet moves it little.
PREDICTION_NEIGHBOURS_PER_PARAMETER = 2
# A threshold is predicted only where a point searched lies this near in the scaled parameters (a
# tenth of each range, the width of an interval called determined); the affine fit then takes
# the nearest ones, that one first. The pulses' outcome need not rise with
# the amplitude far from the threshold: on paper_b, beams 1+2 at 1.5 ms move the sphere at
# 47.6 V and not from there up to their threshold at 54.4 V, so a search started 3 V below it
# ends at 47.6 V. From the middle of the recorded bracket it finds what the device's search did.
PREDICTION_RADIUS_U = 0.1
# The gallop's first step (V) from a guess that is no prediction (the recorded bracket's middle):
# there the model's threshold may lie volts off (paper_e's twelve at `calibrated`, 1.1 to 7 V
# below), and every pulse far above it is dear (0.15-0.3 s against 0.09 near it). Galloping
# from a cell, those twelve took 242 pulses.
UNPREDICTED_STEP_V = 0.5


class ThresholdError(ValueError):
    """A bracket that cannot be used as a threshold observation."""


@dataclasses.dataclass(frozen=True)
class ThresholdObservation:
    """A recorded bracket of one probe step: the threshold lies in ``(low_v, high_v]``, from
    the sphere resting at ``normal_before``."""

    beams: tuple[int, ...]
    width_s: float
    low_v: float
    high_v: float
    normal_before: tuple[float, float, float]

    @classmethod
    def from_bracket(cls, bracket: ProbeBracket) -> ThresholdObservation:
        """The bracket as an observation; a bracket with a side never seen (the threshold
        outside the searched range) or without the resting normal is refused."""
        if (bracket.not_pulled_in_v is None or bracket.pulled_in_v is None
                or bracket.normal_before is None):
            raise ThresholdError(f'{bracket.label}: the bracket has a side never seen or no '
                                 'resting normal; it bounds the threshold on one side only')
        return cls(bracket.beams, bracket.width_s, bracket.not_pulled_in_v,
                   bracket.pulled_in_v, bracket.normal_before)

    @property
    def label(self) -> str:
        beams = '+'.join(str(b) for b in self.beams)
        return f'beam{"s" if len(self.beams) > 1 else ""} {beams}, {self.width_s * 1e3:g} ms'

    @property
    def middle_v(self) -> float:
        return 0.5 * (self.low_v + self.high_v)

    @property
    def std_v(self) -> float:
        """The standard deviation the residual is weighed with (V).

        The bisection is blind inside its last bracket: the device's threshold is equally
        likely anywhere in it, a uniform distribution of standard deviation width / sqrt(12)
        (0.052 V at the protocol's 0.18-0.2 V). The model's own threshold is the middle of a
        bisection to :data:`MODEL_RESOLUTION_V`, uniform in the same way, and it carries the
        model's error (:data:`MODEL_ERROR_V`); the three add in quadrature. A Gaussian of
        that deviation stands in for the uniform so that the misfit is a smooth sum of
        squares whose rise of 3.84 reads a 95 % interval.
        """
        return math.sqrt(((self.high_v - self.low_v) ** 2 + MODEL_RESOLUTION_V ** 2) / 12.0
                         + MODEL_ERROR_V ** 2)


def observations_of(brackets: Iterable[ProbeBracket]) -> tuple[list[ThresholdObservation],
                                                               list[ProbeBracket]]:
    """The brackets that are observations, and those left out (a side never seen)."""
    used, left = [], []
    for bracket in brackets:
        try:
            used.append(ThresholdObservation.from_bracket(bracket))
        except ThresholdError:
            left.append(bracket)
    return used, left


# --- the model's threshold --------------------------------------------------------------------

_cache: OrderedDict[tuple[object, ...], float] = OrderedDict()


class _Probe:
    """One parameter set's model at rest at one recorded normal, pulsed at amplitudes."""

    def __init__(self, params: ParameterSet, beams: tuple[int, ...], width_s: float,
                 normal_before: tuple[float, ...], rtol: float) -> None:
        self.model = process_model(params)
        normal = np.asarray(normal_before, dtype=float)
        self.x_rest = rest_state(self.model, cardan_of_normal(normal / np.linalg.norm(normal)),
                                 relaxation=KICK_RELAXATION)
        self.normal_rest = np.asarray(self.model.surface_normal(self.x_rest), dtype=float)
        self.beams, self.width_s, self.rtol = beams, width_s, rtol
        self.pulses = 0

    def pulls_in(self, amplitude_v: float) -> bool:
        programme = probe_programme(self.beams, self.width_s, amplitude_v, pulses=1)
        end = final_normal(self.model, self.normal_rest, programme, PROBE_SPACING_S, self.rtol,
                           self.x_rest, sample_period_s=PROBE_SPACING_S)
        self.pulses += 1
        return moved_rad(self.normal_rest, end) > PULL_IN_STEP_RAD


def model_threshold_v(params: ParameterSet, beams: Sequence[int], width_s: float,
                      normal_before: Sequence[float], guess_v: float,
                      resolution_v: float = MODEL_RESOLUTION_V, origin_v: float = 0.0,
                      first_step_v: float = MODEL_RESOLUTION_V,
                      rtol: float = FIT_RTOL) -> float:
    """The model's pull-in threshold (V) of one pulse of ``width_s`` on ``beams``, from rest at
    ``normal_before``: the middle of the cell of the lattice of ``resolution_v`` (multiples of
    it from ``origin_v``) whose lower end does not pull in and whose upper end does. A fit puts
    each observation's origin at its recorded bracket's low end, so that the searches'
    lattices are dithered as the device's were
    (:func:`~sphere_sim.fitting.protocol.dithered`) and the model's quantisation of four
    thresholds alike is not one draw shared four times.

    The search starts at the cell holding ``guess_v`` and gallops outwards from it, from a
    step of ``first_step_v`` (doubling), then bisects: a guess in the right cell costs two
    pulses (the cell's two ends), one d cells off some 2 log2(d) more at the first step of one
    cell, and ``log2(first_step_v / resolution_v)`` fewer galloping at a wider first step
    (:data:`UNPREDICTED_STEP_V`, for a guess that is no prediction).
    Where the pulses' outcome rises with the amplitude (none pulls in below the threshold,
    every one above it), the value does not depend on the guess, since the cells are fixed;
    where it does not, the search ends at a switch near the guess
    (:data:`PREDICTION_RADIUS_U` says where that was seen). It keeps to 0 to the device's
    limit: a model that does not pull in below :data:`~msg_defs.device.VOLTAGE_LIMIT_V`
    returns the limit (the residual is then a bound).
    Cached per (parameters, step, resting normal, lattice, tolerance), not per guess.
    """
    key = (params, tuple(int(b) for b in beams), float(width_s),
           tuple(float(v) for v in normal_before), float(resolution_v), float(origin_v),
           float(rtol))
    if key in _cache:
        _cache.move_to_end(key)
        return _cache[key]
    with threadpool_limits(limits=BLAS_THREADS_PER_KICK):
        value = _search(_Probe(params, key[1], key[2], key[3], rtol), guess_v, resolution_v,
                        origin_v, first_step_v)
    _cache[key] = value
    if len(_cache) > CACHE_SIZE:
        _cache.popitem(last=False)
    return value


def _search(probe: _Probe, guess_v: float, resolution_v: float, origin_v: float = 0.0,
            first_step_v: float = MODEL_RESOLUTION_V) -> float:
    # Lattice points k = bottom ... top lie at origin_v + k resolution_v, from the highest at or
    # below 0 V to the highest at or below the device's limit.
    bottom = math.floor(-origin_v / resolution_v + 1e-9)
    top = math.floor((VOLTAGE_LIMIT_V - origin_v) / resolution_v + 1e-9)
    low = min(max(math.floor((guess_v - origin_v) / resolution_v), bottom), top - 1)

    def pulls_in(k: int) -> bool:  # no pulse of 0 V or less pulls in
        amplitude_v = origin_v + k * resolution_v
        return amplitude_v > 0.0 and probe.pulls_in(amplitude_v)

    high, step = low + 1, max(1, round(first_step_v / resolution_v))
    if pulls_in(high):  # it lies at or below the guess's cell: gallop down
        while pulls_in(low):
            high, low = low, max(low - step, bottom)
            step *= 2
    else:  # above it: gallop up
        while True:
            low, high = high, min(high + step, top)
            step *= 2
            if pulls_in(high):
                break
            if high == top:
                return VOLTAGE_LIMIT_V
    while high - low > 1:  # bisect the lattice between the two
        middle = (low + high) // 2
        low, high = (low, middle) if pulls_in(middle) else (middle, high)
    return origin_v + (low + 0.5) * resolution_v


# --- thresholds a bisection does not define ------------------------------------------------------

# A recorded threshold is what a bisection found. Where the pulses' outcome does not rise with
# the amplitude, which switch that is turns on the bisection's path, and the model's search
# (from a guess, galloping) finds the switch nearest its guess: the misfit then has steps.
# paper_b's pair of beams 1+2 at 1.5 ms, at the truth, pulls in from 47.9 to 51.4 V, not
# again until 54.4 V; the device's bisection from (30, 78] V found the upper switch, that of
# beams 3+4 (47.7 to 51.2 V, then from 53.2 V) the lower. Such an observation is scanned
# for before a fit, at the start values, on this window either side of the recorded bracket
# at this step (its gaps are 2-3 V wide, 3-5 V from a switch), and left out.
OUTCOME_WINDOW_V = 8.0
OUTCOME_STEP_V = 0.5
# Pulses in one scan, both ends of the window included.
OUTCOME_PULSES = round(2 * OUTCOME_WINDOW_V / OUTCOME_STEP_V) + 1


def pulse_outcomes(params: ParameterSet, observation: ThresholdObservation,
                   rtol: float = FIT_RTOL) -> tuple[tuple[float, bool], ...]:
    """(amplitude V, pulled in) of one pulse from rest at the recorded normal, at every
    :data:`OUTCOME_STEP_V` from :data:`OUTCOME_WINDOW_V` below the recorded bracket's middle
    to as far above it (within 0 V and the device's limit)."""
    with threadpool_limits(limits=BLAS_THREADS_PER_KICK):
        probe = _Probe(params, observation.beams, observation.width_s,
                       observation.normal_before, rtol)
        amplitudes = [observation.middle_v - OUTCOME_WINDOW_V + k * OUTCOME_STEP_V
                      for k in range(OUTCOME_PULSES)]
        return tuple((a, probe.pulls_in(a)) for a in amplitudes if 0.0 < a <= VOLTAGE_LIMIT_V)


def rises_once(outcomes: Sequence[tuple[float, bool]]) -> bool:
    """True when no pulse pulls in below one that does not: a bisection then finds the one
    switch whatever its path."""
    pulled = [p for _, p in sorted(outcomes)]
    return all(b or not a for a, b in itertools.pairwise(pulled))


def switches_text(outcomes: Sequence[tuple[float, bool]]) -> str:
    """Where the outcome changes, as 'pulls in at 47.9 V, not at 51.4 V, ...'."""
    ordered = sorted(outcomes)
    parts = [f'{"pulls in" if b else "not"} at {a_v:.2f} V' for (_, a), (a_v, b) in
             itertools.pairwise(ordered) if a != b]
    return ', '.join(parts)


def _outcomes_task(task: tuple[ParameterSet, ThresholdObservation, float]
                   ) -> tuple[tuple[float, bool], ...]:
    params, observation, rtol = task
    return pulse_outcomes(params, observation, rtol)


def non_monotone(params: ParameterSet, observations: Sequence[ThresholdObservation],
                 engine: SerialEngine, rtol: float = FIT_RTOL
                 ) -> dict[int, tuple[tuple[float, bool], ...]]:
    """The observations whose pulses, at ``params``, do not rise once with the amplitude
    around the recorded bracket (:func:`rises_once`): index -> the outcomes scanned."""
    scans = engine(_outcomes_task, [(params, o, rtol) for o in observations])
    return {i: scan for i, scan in enumerate(scans) if not rises_once(scan)}


@dataclasses.dataclass(frozen=True)
class SearchCost:
    """One search of the model's threshold, uncached: its value (V), the pulses it simulated
    and its wall time (s), the rest state's included."""

    value_v: float
    pulses: int
    wall_s: float


def search_cost(params: ParameterSet, observation: ThresholdObservation, guess_v: float,
                first_step_v: float = MODEL_RESOLUTION_V,
                rtol: float = FIT_RTOL) -> SearchCost:
    """What :func:`model_threshold_v` costs for ``observation`` from ``guess_v``, on its
    lattice from the bracket's low end, bypassing the cache."""
    started = time.perf_counter()
    with threadpool_limits(limits=BLAS_THREADS_PER_KICK):
        probe = _Probe(params, observation.beams, observation.width_s,
                       observation.normal_before, rtol)
        value = _search(probe, guess_v, MODEL_RESOLUTION_V, observation.low_v, first_step_v)
    return SearchCost(value, probe.pulses, time.perf_counter() - started)


def clear_cache() -> None:
    _cache.clear()


def predicted_thresholds_v(points: ArrayLike, thresholds_v: ArrayLike,
                           u: ArrayLike) -> NDArray[np.float64] | None:
    """Each threshold at the scaled parameter vector ``u``, predicted from those searched at
    ``points`` (m, n) as ``thresholds_v`` (m, t): the affine least-squares fit of the
    :data:`PREDICTION_NEIGHBOURS_PER_PARAMETER` x n nearest, or the nearest alone while
    there are no more than n of them; None where none lies within :data:`PREDICTION_RADIUS_U`
    (a search then starts from the recorded bracket's middle, at :data:`UNPREDICTED_STEP_V`).

    Along a profile or a descent the parameters move a little from point to point and the
    thresholds smoothly with them, so the predicted cell is mostly the right one or next to
    it, and the search (:func:`model_threshold_v`) costs two or three pulses in place of
    seven. Far from every point searched, the search starts where the device's did.
    """
    u = np.asarray(u, dtype=float)
    p = np.asarray(points, dtype=float).reshape(-1, u.size)
    distance = np.linalg.norm(p - u, axis=1)
    if not np.any(distance <= PREDICTION_RADIUS_U):
        return None
    values = np.asarray(thresholds_v, dtype=float).reshape(p.shape[0], -1)
    near = np.argsort(distance, kind='stable')[:PREDICTION_NEIGHBOURS_PER_PARAMETER * u.size]
    if near.size <= u.size:
        return values[near[0]].copy()
    design = np.column_stack([np.ones(near.size), p[near] - u])
    coefficients = np.linalg.lstsq(design, values[near], rcond=None)[0]
    return np.asarray(np.clip(coefficients[0], 0.0, VOLTAGE_LIMIT_V), dtype=float)
