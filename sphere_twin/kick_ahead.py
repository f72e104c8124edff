"""One kick ahead: each recorded pulse programme run alone, from the recorded rest before it,
on the plant that recorded the bag, its landing against the recorded one.

The open-loop replay (:func:`sphere_twin.run_analysis.replay`) runs a whole recording from its
first rest, so one kick's error carries into every later one; near a kick's mirror line, and on
the high pair's pull-in, the rounding decides where a kick lands, and over hundreds of kicks
that measures chaos more than the model. Started from where the device actually rested, each
kick's error is the model's own, which is what a user holding the twin against a device asks.

A kick is run from the recorded resting normal just before it: the last sample at or before
its start that lies after the previous programme's effect was over (its start plus its length
or the kick period, whichever is longer: when the plant reports a programme done). It lands at
the last sample before the next programme starts, or at the last sample of the recording, and
the plant is sampled at every recorded time up to there, as the live simulator advanced. From a
noisy sensor (``average``: the samples before the first command scatter, as
``replay-check`` tells) the resting normals are the means of the resting samples instead, the
recorded landing and the simulated one alike over the settled samples after the kick. A kick
without a rest before it is skipped and said (:class:`SkippedKick`): the kicks are
independent, so no other is lost.

Where the device actually was is known best where the bag records it: a twin's bag carries
its sphere's and beams' state (``/sphere/state``, ``/beams/state``), and the physics then
starts each kick from that state at the last sample before it, its motion included (only the
bristles' strain, which no topic carries, is the rest's at that pose). A device's bag has the
measured normal alone, and a kick starts from the rest at it. On a twin's bag the difference
is what the restart decides on the high pair's pull-in, where a state 1e-6 rad apart can land
1e-3 rad apart (docs/twin.md, "Recording and replaying").
"""

from __future__ import annotations

import concurrent.futures
import dataclasses
import functools
import math
from collections.abc import Callable, Iterator, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from sphere_sim.model.rotations import angle_between
from sphere_sim.twin.plants import TIME_TOL_S
from sphere_twin.run_analysis import (
    UNSTATED_INTEGRATION_METHOD,
    Hold,
    RecordedRun,
    RecordedTruth,
    TruthSample,
    build_replay_plant,
    replayed_normals,
)

if TYPE_CHECKING:
    from sphere_sim.kicks.engine import SerialEngine
    from sphere_sim.model.parameters import ParameterSet

# The percentile reported beside the median and the maximum.
TAIL_PERCENT = 95.0
# Wall seconds between two looks at a running kick (the progress line's own clock decides
# whether to print).
WAIT_S = 1.0
# What each error of replay-check answers (printed in its JSON and docs/twin.md).
ONE_KICK_AHEAD_QUESTION = (
    'is the model right about one kick from where the device actually was: each programme '
    'run alone from the recorded rest before it, its landing against the recorded one')
OPEN_LOOP_QUESTION = (
    'how a whole run drifts: every command replayed from the first rest, so each kick starts '
    'where the replay, not the device, landed; near mirror lines and pull-in steps that '
    'measures chaos, not the model')


@dataclasses.dataclass(frozen=True)
class KickCase:
    """One recorded programme and what its run needs: a worker's whole task.

    Attributes
    ----------
    start_s : float
        Where the programme started.
    normal0 : ndarray, shape (3,)
        The recorded resting normal just before it (the mean of the rest's samples, from a
        noisy sensor).
    times_s, voltages_v : ndarray, shapes (k,) and (k, 4)
        The programme's segments.
    holds : tuple of (time_s, voltages_v (4,))
        The voltage commands from its start to its landing (one can cut it).
    sample_t_s : ndarray, shape (m,), m >= 1
        The recorded sample times after its start, up to its landing (the last).
    landing_samples : int
        How many of the last of them the landing is the mean of (1: the last sample alone).
    recorded_landing : ndarray, shape (3,)
        The recorded normal at the landing.
    truth0 : TruthSample or None
        The recorded sphere and beams at the last sample before it (a twin's bag), or None.
    """

    start_s: float
    normal0: NDArray[np.float64]
    times_s: NDArray[np.float64]
    voltages_v: NDArray[np.float64]
    holds: tuple[Hold, ...]
    sample_t_s: NDArray[np.float64]
    landing_samples: int
    recorded_landing: NDArray[np.float64]
    truth0: TruthSample | None = None

    @property
    def landing_s(self) -> float:
        return float(self.sample_t_s[-1])


@dataclasses.dataclass(frozen=True)
class SkippedKick:
    """A programme that could not be run one kick ahead, and why."""

    start_s: float
    reason: str

    def warning(self) -> str:
        return f'kick at {self.start_s:.3f} s: {self.reason}; skipped'


def kick_cases(run: RecordedRun, window_s: float, average: bool = False,
               truth: RecordedTruth | None = None) -> tuple[list[KickCase], list[SkippedKick]]:
    """The programmes of ``run`` that can be run from a recorded rest, and those that cannot.

    ``window_s`` is the plant's kick period: a programme's effect is over that long after its
    start (or at its end, if later), and the samples from then until the next start are the
    rest it left. With ``average`` (a noisy sensor) a resting normal is the mean of the rest's
    samples, not its last sample. With ``truth`` (a twin's bag) each case carries the recorded
    sphere and beams at the last sample before its start.
    """
    t, normals = run.normal_t_s, run.normals
    cases: list[KickCase] = []
    skipped: list[SkippedKick] = []
    free_s = -math.inf  # when the previous programme's effect was over
    for i, (start_s, times_s, volts_v) in enumerate(run.kicks):
        first = int(np.searchsorted(t, free_s - TIME_TOL_S, side='left'))
        # The sample at the start itself is still at rest: the programme has not acted yet.
        rest_end = int(np.searchsorted(t, start_s + TIME_TOL_S, side='right'))
        next_s = run.kicks[i + 1][0] if i + 1 < len(run.kicks) else math.inf
        land_end = int(np.searchsorted(t, next_s + TIME_TOL_S, side='right'))
        # The last segment switches every beam off: the programme's length.
        free_s = start_s + max(float(times_s[-1]), window_s)
        if rest_end <= first:
            skipped.append(SkippedKick(start_s, 'no rest recorded before it'))
            continue
        if land_end <= rest_end:
            skipped.append(SkippedKick(start_s, 'no sample recorded after its start'))
            continue
        # The landing: the last sample, or the settled ones (at least the last) averaged.
        settled = int(np.searchsorted(t, free_s - TIME_TOL_S, side='left'))
        land_first = min(max(settled, rest_end), land_end - 1) if average else land_end - 1
        landing_s = t[land_end - 1]
        cases.append(KickCase(
            start_s, unit_mean(normals[first if average else rest_end - 1:rest_end]),
            times_s, volts_v,
            tuple(h for h in run.holds
                  if start_s - TIME_TOL_S <= h[0] <= landing_s + TIME_TOL_S),
            t[rest_end:land_end].copy(), land_end - land_first,
            unit_mean(normals[land_first:land_end]),
            None if truth is None else truth.at(float(t[rest_end - 1]))))
    return cases, skipped


def unit_mean(normals: NDArray[np.float64]) -> NDArray[np.float64]:
    """The mean direction of unit normals, shape (n, 3); one normal as it is (bit for bit:
    a table's landing compares exactly)."""
    if len(normals) == 1:
        return np.array(normals[0], dtype=float)
    mean = normals.mean(axis=0)
    return mean / np.linalg.norm(mean)


@dataclasses.dataclass(frozen=True)
class KickAheadResult:
    """The landings of the kicks run one kick ahead (arrays in the order of their starts)."""

    start_s: NDArray[np.float64]
    landing_s: NDArray[np.float64]
    recorded: NDArray[np.float64]  # (k, 3)
    simulated: NDArray[np.float64]  # (k, 3)
    error_rad: NDArray[np.float64]
    skipped: list[SkippedKick]
    averaged: bool = False  # resting normals as the means of their samples (a noisy sensor)
    from_truth: int = 0  # kicks started from the recorded sphere and beams (a twin's bag)

    @property
    def median_rad(self) -> float:
        return float(np.median(self.error_rad)) if self.error_rad.size else math.nan

    @property
    def p95_rad(self) -> float:
        return (float(np.percentile(self.error_rad, TAIL_PERCENT)) if self.error_rad.size
                else math.nan)

    @property
    def max_rad(self) -> float:
        return float(self.error_rad.max()) if self.error_rad.size else math.nan

    @property
    def worst_s(self) -> float:
        return float(self.start_s[np.argmax(self.error_rad)]) if self.error_rad.size \
            else math.nan

    def summary(self) -> str:
        """``median <a> p95 <b> max <c> rad``, as replay-check prints it."""
        return (f'median {self.median_rad:.3g} p95 {self.p95_rad:.3g} max {self.max_rad:.3g} '
                'rad')

    def start_text(self) -> str:
        """Where the kicks started, in words."""
        kicks = int(self.error_rad.size)
        if self.from_truth == 0:
            return 'the rest at the recorded normal'
        text = ('the recorded sphere and beams (the bristles\' strain the rest\'s at that '
                'pose)')
        return text if self.from_truth == kicks else \
            (f'{text} for {self.from_truth} of {kicks}, the rest at the recorded normal for '
             'the others')

    def to_dict(self) -> dict[str, Any]:
        def number(value: float) -> float | None:  # JSON has no NaN
            return value if math.isfinite(value) else None

        return {'question': ONE_KICK_AHEAD_QUESTION, 'kicks': int(self.error_rad.size),
                'median_rad': number(self.median_rad), 'p95_rad': number(self.p95_rad),
                'max_rad': number(self.max_rad), 'worst_time_s': number(self.worst_s),
                'resting_normals': ('the mean of the resting samples (a noisy sensor)'
                                    if self.averaged else 'the last resting sample'),
                'started_from': self.start_text(),
                'skipped': [{'time_s': s.start_s, 'reason': s.reason} for s in self.skipped],
                'per_kick': [{'time_s': float(t), 'landing_s': float(t_land),
                              'recorded': rec.tolist(), 'simulated': sim.tolist(),
                              'error_rad': float(err)}
                             for t, t_land, rec, sim, err in zip(
                                 self.start_s, self.landing_s, self.recorded, self.simulated,
                                 self.error_rad, strict=True)]}


@dataclasses.dataclass(frozen=True)
class ReplayPlantSpec:
    """Which plant a kick runs on: what :func:`~sphere_twin.run_analysis.build_replay_plant`
    takes beside the start (picklable, for the workers)."""

    kind: str
    params: ParameterSet
    tables: tuple[str, ...] = ()
    method: str = UNSTATED_INTEGRATION_METHOD


def run_case(spec: ReplayPlantSpec, case: KickCase) -> NDArray[np.float64] | str:
    """The simulated normal at ``case``'s landing; or, where the model finds no rest at its
    start normal, why (one task of a pool: the kicks are independent)."""
    from threadpoolctl import threadpool_limits

    from sphere_sim.kicks.design import KICK_RELAXATION
    from sphere_sim.kicks.table_build import BLAS_THREADS_PER_KICK
    from sphere_sim.model.initial_state import RestError

    # One BLAS thread, as the table builds: the same landing on every engine.
    with threadpool_limits(limits=BLAS_THREADS_PER_KICK):
        try:
            plant = build_replay_plant(spec.kind, case.normal0, case.start_s, spec.params,
                                       spec.tables, relaxation=KICK_RELAXATION,
                                       truth=case.truth0, method=spec.method)
        except RestError as error:
            return f'no rest of the model at its recorded normal ({error})'
        # Sampled at every recorded time, as the live plant advanced; the last ones are the
        # landing, as the recorded one is taken.
        normals = list(replayed_normals(plant, case.sample_t_s,
                                        [(case.start_s, case.times_s, case.voltages_v)],
                                        case.holds, case.start_s))
        return unit_mean(np.array(normals[-case.landing_samples:]))


def one_kick_ahead(run: RecordedRun, spec: ReplayPlantSpec, window_s: float,
                   engine: SerialEngine, average: bool = False,
                   progress: Callable[[int, int], None] | None = None,
                   truth: RecordedTruth | None = None) -> KickAheadResult:
    """Every programme of ``run`` run alone from the recorded rest before it on the plant of
    ``spec`` (``window_s``: its kick period; ``average``: resting normals as means, for a
    noisy sensor; ``truth``: the recorded sphere and beams of a twin's bag, the physics' start
    where it has the sample; :func:`kick_cases`), the kicks spread over ``engine``'s workers;
    ``progress(done, total)`` after each."""
    cases, skipped = kick_cases(run, window_s, average,
                                truth if spec.kind == 'continuous' else None)
    landed: list[tuple[KickCase, NDArray[np.float64]]] = []
    done = 0

    def say() -> None:
        if progress is not None:
            progress(done, len(cases))

    outcomes = _in_order(engine, functools.partial(run_case, spec), cases, say)
    for case, outcome in zip(cases, outcomes, strict=True):
        if isinstance(outcome, str):
            skipped.append(SkippedKick(case.start_s, outcome))
        else:
            landed.append((case, outcome))
        done += 1
        say()
    skipped.sort(key=lambda s: s.start_s)
    recorded = np.array([c.recorded_landing for c, _ in landed]).reshape(-1, 3)
    simulated = np.array([n for _, n in landed]).reshape(-1, 3)
    return KickAheadResult(
        np.array([c.start_s for c, _ in landed]), np.array([c.landing_s for c, _ in landed]),
        recorded, simulated,
        np.array([angle_between(s, r) for s, r in zip(simulated, recorded, strict=True)]),
        skipped, average, sum(c.truth0 is not None for c, _ in landed))


def _in_order(engine: SerialEngine, func: Callable[[KickCase], NDArray[np.float64] | str],
              cases: Sequence[KickCase],
              waiting: Callable[[], None]) -> Iterator[NDArray[np.float64] | str]:
    """``func`` of each case, in order, each as soon as it and those before it are done. On a
    local pool ``waiting()`` is called every ``WAIT_S`` while a kick is still running: a slow
    one (or workers still compiling) must not silence the progress line."""
    from sphere_sim.kicks.engine import DaskEngine, PoolEngine

    if isinstance(engine, PoolEngine):
        futures = [engine.pool.submit(func, case) for case in cases]
        for future in futures:
            while not concurrent.futures.wait([future], timeout=WAIT_S).done:
                waiting()
            yield future.result()
    elif isinstance(engine, DaskEngine):
        yield from engine(func, cases)
    else:
        yield from map(func, cases)  # in this process
