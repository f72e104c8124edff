"""System identification: fit model parameters so that the continuous model reproduces kicks
recorded on one device.

The kicks come as observations (:mod:`sphere_sim.fitting.observations`): the programme, the
resting normal before it and the resting normal after it, each a mean of settled samples.

The residual of a kick is the model's resting normal after the programme, started at rest at
the recorded normal before it, minus the recorded normal after it (its x and y components, in
rad). Each kick restarts from its own recorded start (multiple shooting): the errors do not
accumulate over a run, and every kick is an independent simulation (one task on a process pool
or Dask).

The fit is :func:`scipy.optimize.least_squares` (trust-region reflective, bounded by the
parameters' ranges) in scaled coordinates (the logarithm of each value, mapped onto [0, 1] over
its range), with a finite-difference Jacobian whose simulations all run as one batch on the
engine. Every evaluated parameter vector and its residuals are appended to a checkpoint file:
the optimiser is deterministic, so a rerun retraces its path from the file and goes on where the
interrupted one stopped.

The residuals are weighed by the sensor noise they carry, correlations included (the
observations' ``whitener``). Each declared parameter's range enters as a weak prior
(``PRIOR_SD_UNIT``).

Before fitting, the Jacobian at the start says what the recordings can tell: a parameter whose
expected uncertainty spans its whole range is held at its start value and reported as
unresolved; one almost perfectly correlated with another (an unidentifiable pair) is reported
as entangled, and fitted with an interval that spans what the kicks leave open. That interval
is measured on the misfit itself (``_scan_checked``), never taken from the Jacobian alone.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import os
from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any, cast

import numpy as np
from numpy.typing import ArrayLike, NDArray
from threadpoolctl import threadpool_limits

from sphere_sim.fitting import misfit_scan as scan
from sphere_sim.fitting.observations import (
    SETTLE_S,
    IdentificationError,
    KickObservation,
    Observations,
)
from sphere_sim.fitting.ramps import PullInObservation, RampObservation, model_ramp_pull_in_v
from sphere_sim.fitting.thresholds import (
    MODEL_RESOLUTION_V,
    UNPREDICTED_STEP_V,
    ThresholdObservation,
    model_threshold_v,
    predicted_thresholds_v,
)
from sphere_sim.integrate.tolerances import FIT_RTOL
from sphere_sim.kicks.design import (
    KICK_RELAXATION,
    KICK_SAMPLE_PERIOD_S,
    cardan_of_normal,
    final_normal,
)
from sphere_sim.kicks.engine import SerialEngine, engine_for
from sphere_sim.kicks.process_models import process_model
from sphere_sim.kicks.table_build import BLAS_THREADS_PER_KICK
from sphere_sim.model.initial_state import rest_state
from sphere_sim.model.parameters import ParameterSet

# Why a parameter was set aside (:func:`select_identifiable`): its status, its partner (an
# entangled one's) and the cosine of their effects.
SetAside = tuple[str, int | None, float]

# The fit's tolerance, a tenth of the live twin's (sphere_sim.twin.plants.LIVE_RTOL). At the
# live 3e-4 a kick ends within a few 1e-6 rad of the exact one, but that error jumps with the
# step-size sequence as a parameter moves, and over 40 kicks the jumps moved the whitened misfit
# by 2 to 4 within a standard error of the optimum (device_a): local dips deeper than the
# interval's rise of 4, which the optimiser stopped in and the scan read as curvature. At 3e-5
# the same line is a smooth parabola, equal to 3e-6's within 0.05, for 14 % more work.
# The set `identify` starts from unless told: the paper's device (`calibrated`), the default
# set of every command, whose experiment protocol determines the beams' parameters
# (docs/identification.md, "An experiment protocol"). A device of the dry, holding contact
# (`dry_contact`, device_a to device_e) is identified from that set with `--params dry_contact`.
START_PARAMETER_SET = 'calibrated'
# A kick whose end the model does not determine tells nothing of the parameters, and its jumps
# as they move make the misfit rough. On the paper's device some kicks land so: paper_a's first
# (intensity 0.75, the high pair 4.2 ms) ends 3e-4 rad apart at rtol 1e-5, 1e-6 and 1e-7
# without converging, its landing after the sliding impact turning on differences below any
# tolerance (one of paper_b's 40 kicks from 0.5 to 1 was left out); most others, and the dry
# contact's, agree within a few 1e-6. Each kick is simulated at the start values at the fit's
# tolerance and at this fraction of it, and one whose two ends differ by more than its
# residual's standard deviation is left out.
DETERMINACY_RTOL_FACTOR = 0.1
# Nor does the model determine a kick whose end turns sharply on where it starts: the restart
# knows its start only to the residual's standard deviation σ (the mean's noise, and the state
# beyond the normal that a restart from rest lacks). A kick started δ off along x or along y
# whose end moves by more than δ beyond that shift is left out, with δ = σ but at least
# START_PROBE_RAD: below it the integrator's own jitter at the fit's tolerance (up to 3e-5 rad
# on the paper's device) would read as the kick's response. On the paper's device these are
# the kicks near a landing's branch point (noiseless protocol recordings, at the truth):
# paper_d's 17th of 20 moves 5.5 times its start's shift and ends 1e-3 rad from the continuous
# run that recorded it, paper_e's 1st 27 times and 2.3e-4 rad; the kicks kept move within 0.6
# of their shift (docs/identification.md).
START_PROBE_RAD = 1e-4
# The starts' shifts, one unit along x and along y.
START_SHIFTS = (np.array([1.0, 0.0]), np.array([0.0, 1.0]))
# What undetermined_kicks simulates of each kick: the start values at two tolerances and the
# shifted starts.
DETERMINACY_SIMULATIONS_PER_KICK = 2 + len(START_SHIFTS)
# Finite-difference step in the scaled coordinate ([0, 1] over the range, logarithmic). The
# integrator's error jumps as a parameter moves (a few 1e-6 rad); divided by the step, the jumps
# must stay well below what a residual's noise can tell, or the Jacobian reads them as
# information about a combination the kicks do not tell (an entangled pair's valley): at 0.01
# they did. The step must also stay below the width of the valleys the whitened misfit has
# (one standard error, 0.01 to 0.05 with 40 kicks), or the Gauss-Newton steps miss their floor.
# The misfit's curvature is then measured over the reported interval itself (misfit_scan).
FD_STEP = 0.02
# An undeclared parameter named for the fit is searched within this factor of its start value:
# a search bound of the identification, not a physical range (docs/identification.md).
UNDECLARED_FACTOR = 2.0
# A declared range is where the parameter physically lies: the fit takes it as a Gaussian
# prior about the start value whose two standard deviations span half the scaled range. It
# decides only what the kicks leave open (an entangled pair's valley); a parameter they pin
# moves as the kicks say. An undeclared parameter has no prior.
PRIOR_SD_UNIT = 0.25
# What the recordings cannot tell: a parameter whose 2-sigma interval, with the ones fitted
# before it held, would cover more than this share of its scaled range; or one of a pair whose
# estimates would correlate beyond PAIR_CORRELATION_LIMIT.
UNRESOLVED_SHARE = 0.5
PAIR_CORRELATION_LIMIT = 0.95
# The optimiser stops when a step moves the scaled parameters by less than XTOL (a tenth of the
# smallest standard errors that recordings of tens of kicks give) or the cost by less than FTOL
# of itself; the scan of the misfit then checks the optimum (RESTART_DROP).
XTOL = 1e-3
FTOL = 1e-4
# The scan of the misfit: at most SCAN_ROUNDS, until each direction's rise two standard errors
# out is 4 within SCAN_AGREEMENT in the standard error; one round may widen or narrow a
# direction's variance at most MAX_WIDENING times. A point lower than the optimum by
# RESTART_DROP (a sum of squares of 1: one standard error) restarts the optimiser there.
SCAN_ROUNDS = 3
SCAN_AGREEMENT = 1.5
MAX_WIDENING = 25.0
RESTART_DROP = 1.0
# The optimiser starts from the start values, the centre of the prior, and from the lowest
# OPTIMISER_STARTS of a design of STARTS_PER_PARAMETER points per parameter over the region the
# priors allow. The design's lowest can all lie on one side of a ridge in a valley (device_b's
# damping and friction: both ended 4.6 standard errors from the truth, at a misfit 9 higher).
STARTS_PER_PARAMETER = 6
OPTIMISER_STARTS = 1
MAX_RESTARTS = 2
# The reported interval: this many standard errors either side (about 95 % for a Gaussian
# estimate), in the scaled coordinate, so that it is a factor either way in the value.
UNCERTAINTY_SIGMAS = 2.0
# 2: the model's thresholds are the cells of a fixed lattice (thresholds.model_threshold_v).
CHECKPOINT_VERSION = 2


# --- the parameters fitted ------------------------------------------------------------------------

@dataclasses.dataclass(frozen=True)
class FitParameter:
    """A parameter the fit moves, within ``[low, high]`` (scaled logarithmically).

    ``declared`` tells a range declared uncertain in the parameter set (with its physical
    reason) from the search bound an undeclared name gets (``UNDECLARED_FACTOR``).
    """

    path: str
    low: float
    high: float
    tied: tuple[str, ...] = ()
    declared: bool = True

    def __post_init__(self) -> None:
        if not (self.low * self.high > 0 and self.low < self.high):
            raise IdentificationError(f'{self.path}: the range [{self.low:g}, {self.high:g}] '
                                      'must lie on one side of zero')

    @property
    def _log_bounds(self) -> tuple[float, float]:
        a, b = math.log(abs(self.low)), math.log(abs(self.high))
        return min(a, b), max(a, b)

    @property
    def sign(self) -> float:
        return 1.0 if self.low > 0 else -1.0

    def to_unit(self, value: float) -> float:
        lo, hi = self._log_bounds
        return (math.log(abs(value)) - lo) / (hi - lo)

    def from_unit(self, u: float) -> float:
        lo, hi = self._log_bounds
        if not 0.0 < u < 1.0:  # a range's end exactly, not an ulp off
            near_zero, far = (self.low, self.high) if self.sign > 0 else (self.high, self.low)
            return near_zero if u <= 0.0 else far
        return self.sign * math.exp(lo + float(u) * (hi - lo))

    def assign(self, value: float) -> dict[str, float]:
        return {path: value for path in (self.path, *self.tied)}


def fit_parameters(params: ParameterSet,
                   names: Sequence[str] | None = None) -> list[FitParameter]:
    """The parameters to fit: those ``params`` declares uncertain, or the paths ``names``.

    A named path that is declared uncertain keeps its declared range and ties; any other gets
    ``UNDECLARED_FACTOR`` either side of its value in ``params``.

    Raises
    ------
    IdentificationError
        For an unknown path, a non-numeric one, or one at zero (no scale to search on).
    """
    declared = {u.path: u for u in params.uncertain}
    tied_to = {t: u.path for u in params.uncertain for t in u.tied}
    if not names:
        return [FitParameter(u.path, u.low, u.high, u.tied) for u in params.uncertain]
    fits, seen = [], set()
    for name in names:
        name = tied_to.get(name, name)
        if name in seen:
            continue
        seen.add(name)
        try:
            value = params.get(name)
        except AttributeError:
            raise IdentificationError(f'unknown parameter {name!r}') from None
        if isinstance(value, bool) or not isinstance(value, float) or dataclasses.is_dataclass(
                value):
            raise IdentificationError(f'{name} is not a number that can be fitted')
        if name in declared:
            u = declared[name]
            fits.append(FitParameter(u.path, u.low, u.high, u.tied))
        elif value == 0.0:
            raise IdentificationError(f'{name} is 0 and declared nowhere uncertain: there is no '
                                      'scale to search it on')
        else:
            a, b = value / UNDECLARED_FACTOR, value * UNDECLARED_FACTOR
            fits.append(FitParameter(name, min(a, b), max(a, b), declared=False))
    return fits


def params_at(params: ParameterSet, fits: Sequence[FitParameter],
              values: Iterable[float]) -> ParameterSet:
    """``params`` with each fitted path (and its ties) set to ``values``."""
    assigned = {}
    for fit, value in zip(fits, values, strict=True):
        assigned.update(fit.assign(float(value)))
    return params.replace(**assigned)


# --- one kick, one task ---------------------------------------------------------------------------

def kick_end_normal(params: ParameterSet, kick: KickObservation,
                    rtol: float = FIT_RTOL) -> NDArray[np.float64]:
    """The model's resting normal after ``kick``'s programme, from rest at its recorded start."""
    with threadpool_limits(limits=BLAS_THREADS_PER_KICK):
        model = process_model(params)
        x_rest = rest_state(model, cardan_of_normal(kick.normal_before),
                            relaxation=KICK_RELAXATION)
        window = max(SETTLE_S, float(kick.times_s[-1]))
        return np.asarray(final_normal(model, kick.normal_before, kick.programme(), window,
                                       rtol, x_rest,
                                       sample_period_s=max(window, KICK_SAMPLE_PERIOD_S)),
                          dtype=float)


# One simulation's inputs: the parameters, the observation, the tolerance, and for a threshold
# its predicted value, where its search starts (V; None: no prediction, the search starts at the
# recorded bracket's middle with a wide step).
ObservationTask = tuple[ParameterSet, KickObservation | PullInObservation, float,
                        float | None]


def _observation_task(task: ObservationTask) -> NDArray[np.float64]:
    """One simulation of one observation: a kick's end normal, or a threshold or a ramp's
    pull-in (V, one entry)."""
    params, observation, rtol, guess_v = task
    if isinstance(observation, RampObservation):
        return np.array([model_ramp_pull_in_v(params, observation, rtol)])
    if isinstance(observation, ThresholdObservation):
        start_v, step_v = ((observation.middle_v, UNPREDICTED_STEP_V) if guess_v is None
                           else (guess_v, MODEL_RESOLUTION_V))
        return np.array([model_threshold_v(params, observation.beams, observation.width_s,
                                           observation.normal_before, start_v,
                                           origin_v=observation.low_v, first_step_v=step_v,
                                           rtol=rtol)])
    return kick_end_normal(params, observation, rtol)


def undetermined_kicks(params: ParameterSet, observations: Observations, engine: SerialEngine,
                       rtol: float = FIT_RTOL) -> tuple[int, ...]:
    """Indices of the kicks whose end the model at ``params`` does not determine: at ``rtol``
    and at ``DETERMINACY_RTOL_FACTOR`` of it they end further apart than the residual's
    standard deviation σ (:meth:`Observations.residual_std_rad`), or started δ off along x or
    y (δ = σ, at least ``START_PROBE_RAD``) they end further than δ from the end moved by
    that shift."""
    kicks = observations.kicks
    n = len(kicks)
    sigmas = [observations.residual_std_rad(i) for i in range(n)]
    probes = [max(sigma, START_PROBE_RAD) for sigma in sigmas]
    tasks: list[ObservationTask] = [(params, kick, r, None) for r in (
        rtol, rtol * DETERMINACY_RTOL_FACTOR) for kick in kicks]
    tasks += [(params, dataclasses.replace(
        kick, normal_before=_shifted(kick.normal_before, probe * shift)), rtol, None)
        for shift in START_SHIFTS for kick, probe in zip(kicks, probes, strict=True)]
    ends = [np.asarray(e)[:2] for e in engine(_observation_task, tasks)]
    left_out = []
    for i in range(n):
        apart = np.linalg.norm(ends[i] - ends[n + i])
        moved = max(np.linalg.norm(ends[(2 + k) * n + i] - ends[i] - probes[i] * shift)
                    for k, shift in enumerate(START_SHIFTS))
        if apart > sigmas[i] or moved > probes[i]:
            left_out.append(i)
    return tuple(left_out)


def _shifted(normal: NDArray[np.float64], shift_xy: NDArray[np.float64]) -> NDArray[np.float64]:
    """The unit normal whose x and y are ``normal``'s moved by ``shift_xy`` (rad, small)."""
    xy = np.asarray(normal, dtype=float)[:2] + shift_xy
    return np.array([xy[0], xy[1], math.sqrt(1.0 - float(xy @ xy))])


def kick_residuals(observations: Observations,
                   ends: Sequence[ArrayLike]) -> NDArray[np.float64]:
    """Residual vector (2 per kick: x and y of model minus recorded resting normal, rad)."""
    return np.concatenate([(np.asarray(end) - k.normal_after)[:2]
                           for k, end in zip(observations.kicks, ends, strict=True)])


# --- evaluations, cached and checkpointed ---------------------------------------------------------

class Evaluator:
    """Residuals at scaled parameter vectors, each simulated once (in batches on an engine)
    and appended to a checkpoint file that a rerun reads back.

    A vector holds the kicks' residuals (x and y of each, rad) and then, for each of
    ``thresholds`` (the experiment protocol's searches and slow ramps), the model's threshold
    or ramp pull-in (V): every simulation of one parameter vector is one task on the engine,
    kicks and thresholds alike.
    """

    def __init__(self, params: ParameterSet, observations: Observations,
                 fits: Sequence[FitParameter], engine: SerialEngine, rtol: float = FIT_RTOL,
                 checkpoint: str | Path | None = None,
                 progress: Callable[[Evaluator], object] | None = None,
                 thresholds: Sequence[PullInObservation] = (),
                 predicted_from: Sequence[Evaluator] = ()) -> None:
        self.params, self.obs, self.fits = params, observations, fits
        self.thresholds = tuple(thresholds)
        # Evaluators of the same thresholds and fits whose searches predict this one's too
        # (the joint fit's, from the search on the thresholds alone that came before it).
        self.predicted_from = tuple(predicted_from)
        self.engine, self.rtol, self.progress = engine, rtol, progress
        self.cache: dict[tuple[str, ...], NDArray[np.float64]] = {}
        self.simulated = 0  # kicks simulated
        self.searched = 0  # thresholds searched
        self._written = False  # this run has started its own checkpoint file
        self.checkpoint = Path(checkpoint) if checkpoint is not None else None
        self.digest = self._digest()
        self.resumed = self._read_checkpoint()

    def _digest(self) -> str:
        text = json.dumps({'version': CHECKPOINT_VERSION, 'params': self.params.digest(),
                           'observations': self.obs.digest(), 'rtol': self.rtol,
                           'fits': [dataclasses.asdict(f) for f in self.fits]}
                          | ({'thresholds': [dataclasses.asdict(t) for t in self.thresholds]}
                             if self.thresholds else {}),
                          sort_keys=True, default=list)
        return hashlib.sha256(text.encode()).hexdigest()[:16]

    @staticmethod
    def key(u: ArrayLike) -> tuple[str, ...]:
        return tuple(float(v).hex() for v in np.asarray(u, dtype=float))

    def _read_checkpoint(self) -> int:
        if self.checkpoint is None or not self.checkpoint.exists():
            return 0
        with open(self.checkpoint) as stream:
            try:
                header = json.loads(stream.readline() or '{}')
            except json.JSONDecodeError:
                return 0
            if header.get('digest') != self.digest:
                return 0
            for line in stream:
                try:
                    entry = json.loads(line)
                except json.JSONDecodeError:
                    break  # cut short by the interruption
                self.cache[tuple(entry['u'])] = np.array(entry['r'], dtype=float)
        return len(self.cache)

    def _append(self, entries: Iterable[tuple[tuple[str, ...], NDArray[np.float64]]]) -> None:
        if self.checkpoint is None:
            return
        if self._written:
            with open(self.checkpoint, 'a') as stream:
                stream.writelines(self._line(key, r) for key, r in entries)
            return
        # This run's first write starts the file anew with every evaluation it holds (those read
        # back included): appended to a line an interruption cut short, they would be lost on
        # the next resume. The old file stays whole until the new one replaces it.
        fresh = self.checkpoint.with_name(self.checkpoint.name + '.tmp')
        with open(fresh, 'w') as stream:
            stream.write(json.dumps({'digest': self.digest}) + '\n')
            stream.writelines(self._line(key, r) for key, r in self.cache.items())
        os.replace(fresh, self.checkpoint)
        self._written = True

    @staticmethod
    def _line(key: tuple[str, ...], r: NDArray[np.float64]) -> str:
        return json.dumps({'u': list(key), 'r': r.tolist()}) + '\n'

    def values(self, u: Iterable[float]) -> list[float]:
        return [fit.from_unit(v) for fit, v in zip(self.fits, u, strict=True)]

    def many(self, points: Sequence[ArrayLike]) -> list[NDArray[np.float64]]:
        """Residual vectors at each scaled point; the uncached ones simulated in one batch."""
        keys = [self.key(u) for u in points]
        todo = list(dict.fromkeys(k for k in keys if k not in self.cache))
        if todo:
            # Every point's threshold searches are queued before any kick: they are the
            # longer tasks (several pulses each), and a pool that takes the longest first
            # ends the batch with both workers busy instead of one finishing a search alone.
            searches: list[ObservationTask] = []
            kicks: list[ObservationTask] = []
            for key in todo:
                u = [float.fromhex(v) for v in key]
                p = params_at(self.params, self.fits, self.values(u))
                kicks += [(p, kick, self.rtol, None) for kick in self.obs.kicks]
                predicted = self.predicted_thresholds_v(u)
                searches += [(p, threshold, self.rtol,
                              None if predicted is None else float(predicted[i]))
                             for i, threshold in enumerate(self.thresholds)]
            results = self.engine(_observation_task, searches + kicks)
            n, m = len(self.obs.kicks), len(self.thresholds)
            found, ends = results[:m * len(todo)], results[m * len(todo):]
            self.simulated += n * len(todo)
            self.searched += m * len(todo)
            entries = []
            for i, key in enumerate(todo):
                mine = ends[i * n:(i + 1) * n]
                r = np.concatenate([kick_residuals(self.obs, mine) if n else np.zeros(0),
                                    *found[i * m:(i + 1) * m]])
                self.cache[key] = r
                entries.append((key, r))
            self._append(entries)
        if self.progress is not None:
            self.progress(self)
        return [self.cache[k] for k in keys]

    def __call__(self, u: ArrayLike) -> NDArray[np.float64]:
        return self.many([u])[0]

    def predicted_thresholds_v(self, u: ArrayLike) -> NDArray[np.float64] | None:
        """Where each threshold's search at ``u`` starts: predicted from those already
        searched (:func:`~sphere_sim.fitting.thresholds.predicted_thresholds_v`), which sets
        the search's cost and not its value; None with no point searched near."""
        if not self.thresholds:
            return None
        points, values = [], []
        for evaluator in (self, *self.predicted_from):
            rows = 2 * len(evaluator.obs.kicks)
            points += [[float.fromhex(v) for v in key] for key in evaluator.cache]
            values += [r[rows:] for r in evaluator.cache.values()]
        return predicted_thresholds_v(points, values, u)

    def jacobian(self, u: ArrayLike, step: float = FD_STEP) -> NDArray[np.float64]:
        """Forward differences (backward at the range's top), all columns in one batch."""
        u = np.asarray(u, dtype=float)
        points, steps = [u], []
        for j in range(u.size):
            h = step if u[j] + step <= 1.0 else -step
            shifted = u.copy()
            shifted[j] += h
            points.append(shifted)
            steps.append(h)
        r = self.many(points)
        return np.column_stack([(r[j + 1] - r[0]) / steps[j] for j in range(u.size)])


# --- what the recordings can tell -----------------------------------------------------------------

def covariance(jac_w: NDArray[np.float64]) -> NDArray[np.floating[Any]]:
    """``(J^T J)^-1`` of whitened residuals with Jacobian ``jac_w`` (pseudo-inverse)."""
    return np.linalg.pinv(jac_w.T @ jac_w)


def select_identifiable(jac_w: ArrayLike) -> tuple[list[int], dict[int, SetAside]]:
    """Which parameters the recordings can tell, and what the others are.

    Orthogonal selection on the whitened Jacobian ``jac_w`` (residuals in units of their
    noise): take the parameter the residuals are most sensitive to, remove its direction from
    the others, and go on while the next one's remaining sensitivity still pins it to
    ``UNRESOLVED_SHARE`` of its range at ``UNCERTAINTY_SIGMAS``; then, while two selected ones
    would have estimates correlated beyond ``PAIR_CORRELATION_LIMIT``, set aside the less
    sensitive of them. A parameter set aside is *unresolved* when even alone it could not be
    pinned so, and otherwise *entangled*: its effect on the kicks is (nearly) a combination of
    those selected, and its partner is the selected one whose effect it resembles most.

    Returns
    -------
    selected : list of int
    why : dict of int -> (status, partner index or None, cosine of their effects)
    """
    jw = np.asarray(jac_w, dtype=float)
    p = jw.shape[1]
    limit = UNCERTAINTY_SIGMAS / UNRESOLVED_SHARE
    selected: list[int]
    selected, remaining = [], list(range(p))
    while remaining:
        res = jw
        if selected:
            q, _ = np.linalg.qr(jw[:, selected])
            res = jw - q @ (q.T @ jw)
        norms = np.linalg.norm(res, axis=0)
        best = max(remaining, key=lambda j: norms[j])
        if norms[best] < limit:
            break
        selected.append(best)
        remaining.remove(best)
    alone = np.linalg.norm(jw, axis=0)
    # A pair whose estimates would correlate beyond the limit: each alone may be pinned, but
    # the kicks trade one for the other.
    while len(selected) > 1:
        cov = covariance(jw[:, selected])
        sd = np.sqrt(np.diag(cov))
        corr = np.abs(cov / np.outer(sd, sd)) - np.eye(len(selected))
        a, b = np.unravel_index(np.argmax(corr), corr.shape)
        if corr[a, b] <= PAIR_CORRELATION_LIMIT:
            break
        weak = selected[a] if alone[selected[a]] < alone[selected[b]] else selected[b]
        selected.remove(weak)
        remaining.append(weak)
    why: dict[int, SetAside] = {}
    for j in remaining:
        if alone[j] < limit or not selected:
            why[j] = ('unresolved', None, 0.0)
            continue
        cos = [float(jw[:, j] @ jw[:, k] / (alone[j] * alone[k])) for k in selected]
        k = int(np.argmax(np.abs(cos)))
        why[j] = ('entangled', selected[k], cos[k])
    return selected, why


# --- the misfit -----------------------------------------------------------------------------------

class Misfit:
    """The sum of squares the fit minimises: the kicks' residuals whitened by the sensor
    noise, and for each declared parameter its prior, a Gaussian about the start value with
    ``PRIOR_SD_UNIT`` (its range is where it physically lies). The prior decides only what the
    kicks leave open: along an entangled pair's valley, not across it."""

    def __init__(self, evaluator: Evaluator, whitener: ArrayLike,
                 fits: Sequence[FitParameter], start: ArrayLike) -> None:
        self.ev, self.whitener = evaluator, np.asarray(whitener, dtype=float)
        self.start = np.asarray(start, dtype=float)
        self.prior = np.array([f.declared for f in fits], dtype=bool)

    def data(self, r: NDArray[np.float64]) -> NDArray[np.float64]:
        return self.whitener @ r

    def prior_residuals(self, u: ArrayLike) -> NDArray[np.float64]:
        return ((np.asarray(u, dtype=float) - self.start) / PRIOR_SD_UNIT)[self.prior]

    def residuals(self, u: ArrayLike) -> NDArray[np.float64]:
        return np.concatenate([self.data(self.ev(u)), self.prior_residuals(u)])

    def chi2_many(self, points: Sequence[ArrayLike]) -> NDArray[np.float64]:
        return np.array([float(np.sum(self.data(r) ** 2) + np.sum(self.prior_residuals(u) ** 2))
                         for u, r in zip(points, self.ev.many(points), strict=True)])

    def chi2(self, u: ArrayLike) -> float:
        return float(self.chi2_many([u])[0])

    def jacobian(self, u: ArrayLike) -> NDArray[np.float64]:
        rows = np.eye(self.start.size)[self.prior] / PRIOR_SD_UNIT
        return np.vstack([self.whitener @ self.ev.jacobian(u), rows])


# --- the fit --------------------------------------------------------------------------------------

@dataclasses.dataclass
class FittedParameter:
    path: str
    start: float
    value: float
    # (low, high): UNCERTAINTY_SIGMAS standard errors either side; () if held
    interval: tuple[float, ...]
    low: float
    high: float
    declared: bool
    status: str  # 'fitted'; 'entangled' (fitted: the kicks tell a combination with another);
    # 'unresolved' (held at its start value)
    note: str = ''
    tied: tuple[str, ...] = ()

    @property
    def fitted(self) -> bool:
        return self.status != 'unresolved'

    def contains(self, value: float) -> bool:
        """Whether ``value`` lies in the reported interval (a held parameter: at its value)."""
        if not self.fitted:
            return math.isclose(value, self.value, rel_tol=1e-12)
        return min(self.interval) <= value <= max(self.interval)

    def to_dict(self) -> dict[str, Any]:
        return {'path': self.path, 'tied': list(self.tied), 'start': self.start,
                'value': self.value,
                'interval': [float(v) for v in self.interval] if self.fitted else None,
                'range': [self.low, self.high], 'declared_range': self.declared,
                'status': self.status, 'note': self.note}


@dataclasses.dataclass
class IdentificationResult:
    parameters: list[FittedParameter]  # in the order asked
    vectors_before: NDArray[np.float64]  # (k, 2): x and y of model minus recorded, at the start
    vectors_after: NDArray[np.float64]  # (k, 2): the same at the fitted values
    noise_std_rad: float
    correlation: NDArray[np.float64]  # among the fitted ones, at the optimum
    evaluations: int
    simulated_kicks: int
    resumed_evaluations: int
    converged: str
    cost_ratio: float  # the kicks' whitened sum of squares after over its degrees of freedom
    restarts: int = 0  # optimiser runs restarted from a lower point the scan found
    # The kicks fitted (those the model determines), and the indices of those left out in the
    # observations given (undetermined_kicks); None: all given were fitted.
    observations: Observations | None = None
    undetermined: tuple[int, ...] = ()

    @property
    def residuals_before(self) -> NDArray[np.float64]:
        """Per kick: angle (rad) between the model's and the recorded resting normal."""
        return np.hypot(*self.vectors_before.T)

    @property
    def residuals_after(self) -> NDArray[np.float64]:
        return np.hypot(*self.vectors_after.T)

    def fitted(self) -> list[FittedParameter]:
        return [p for p in self.parameters if p.fitted]

    def values(self) -> dict[str, float]:
        return {p.path: p.value for p in self.parameters}


def identify(params: ParameterSet, observations: Observations, fits: Iterable[FitParameter],
             workers: int | SerialEngine = 1, scheduler: str | None = None,
             rtol: float = FIT_RTOL, checkpoint: str | Path | None = None,
             progress: Callable[[Evaluator], object] | None = None,
             max_nfev: int = 30) -> IdentificationResult:
    """Fit ``fits`` so that the model reproduces ``observations``.

    Parameters
    ----------
    params : ParameterSet
        The start (and every parameter not fitted).
    observations : Observations
    fits : sequence of FitParameter
    workers : int or engine
        Local processes (ignored with ``scheduler``) or a started engine (left open).
    scheduler : str, optional
        Dask scheduler address.
    checkpoint : path, optional
        Evaluations file, appended as they are made and read back by a rerun.
    progress : callable, optional
        Called with the :class:`Evaluator` after each batch.
    max_nfev : int
        Most residual evaluations of each optimiser run (each one a batch of kicks).
    """
    fits = list(fits)
    if not fits:
        raise IdentificationError('nothing to fit: name parameters with --fit, or use a '
                                  'parameter set that declares some uncertain')
    _enough_kicks(len(observations.kicks), len(fits), '')
    start = np.array([min(max(f.to_unit(params.get(f.path)), 0.0), 1.0) for f in fits])
    with engine_for(workers, scheduler) as engine:
        undetermined = undetermined_kicks(params, observations, engine, rtol)
        observations = observations.without(undetermined)
        _enough_kicks(len(observations.kicks), len(fits),
                      f' ({len(undetermined)} left out: the model does not determine them)')
        whitener = observations.whitener()
        ev = Evaluator(params, observations, fits, engine, rtol, checkpoint, progress)
        misfit = Misfit(ev, whitener, fits, start)
        why = select_identifiable(whitener @ ev.jacobian(start))[1]
        r0 = ev(start)
        free = [j for j in range(len(fits)) if why.get(j, ('',))[0] != 'unresolved']
        u, converged, cov_free, restarts = start.copy(), 'nothing fitted', np.zeros((0, 0)), 0
        if free:
            u, converged = _best_of_starts(misfit, start, fits, free, max_nfev)
            u, converged, cov_free, restarts = _scan_checked(misfit, u, converged, free,
                                                                max_nfev)
        r1 = ev(u)
    chi2 = float(np.sum(misfit.data(r1) ** 2)) / max(1, r1.size - len(free))
    # The sensor noise sets the scale; a fit worse than it explains widens the errors too.
    scale = max(1.0, chi2)
    notes = _notes(fits, why)
    results = []
    for j, fit in enumerate(fits):
        start_value = params.get(fit.path)
        status, note = notes.get(j, ('fitted', ''))
        if j not in free:
            results.append(FittedParameter(fit.path, start_value, start_value, (), fit.low,
                                           fit.high, fit.declared, status, note, fit.tied))
            continue
        k = free.index(j)
        half = UNCERTAINTY_SIGMAS * math.sqrt(max(cov_free[k, k], 0.0) * scale)
        ends = (fit.from_unit(max(u[j] - half, 0.0)), fit.from_unit(min(u[j] + half, 1.0)))
        results.append(FittedParameter(
            fit.path, start_value, fit.from_unit(u[j]), (min(ends), max(ends)), fit.low,
            fit.high, fit.declared, status, note, fit.tied))
    sig = np.sqrt(np.clip(np.diag(cov_free), 1e-300, None))
    corr = cov_free / np.outer(sig, sig) if free else cov_free
    return IdentificationResult(results, r0.reshape(-1, 2), r1.reshape(-1, 2),
                                observations.noise_std_rad, corr, len(ev.cache),
                                ev.simulated + 2 * (len(observations.kicks) + len(undetermined)),
                                ev.resumed, converged, chi2, restarts, observations,
                                undetermined)


def _enough_kicks(kicks: int, fits: int, why_fewer: str) -> None:
    if kicks * 2 <= fits:
        raise IdentificationError(f'{kicks} kicks{why_fewer} cannot fit {fits} parameters: '
                                  'record more')


def _scan_checked(misfit: Misfit, u: NDArray[np.float64], converged: str, free: list[int],
                  max_nfev: int) -> tuple[NDArray[np.float64], str, NDArray[np.float64], int]:
    """The optimum's covariance (scaled coordinates of ``free``) from the misfit itself.

    Starting from the Gauss-Newton covariance, the misfit is evaluated two standard errors
    either way along each principal direction (``misfit_scan``), and each direction's variance
    is rescaled by what the rise there says; a direction whose rise was not about 4 (outside
    ``SCAN_AGREEMENT``) is scanned again at its new scale, at most ``SCAN_ROUNDS`` times. A
    point lower than the optimum by more than ``RESTART_DROP`` means the optimiser stopped
    short in a valley: it restarts from there (at most ``MAX_RESTARTS`` times).

    Returns
    -------
    u, converged, cov, restarts
    """
    restarts = 0
    while True:
        scales, vectors = scan.principal_scales(covariance(misfit.jacobian(u)[:, free]))
        chi_opt = misfit.chi2(u)
        todo, better = list(range(scales.size)), None
        for _ in range(SCAN_ROUNDS):
            points = [_embed(u, free, sign * scan.SCAN_SIGMAS * scales[k] * vectors[:, k])
                      for k in todo for sign in (1.0, -1.0)]
            chis = misfit.chi2_many(points)
            best = int(np.argmin(chis))
            if chis[best] < chi_opt - RESTART_DROP and restarts < MAX_RESTARTS:
                better = points[best]
                break
            still = []
            for i, k in enumerate(todo):
                # How far each point got along its direction (a bound may clip it), in the
                # standard errors scanned.
                t = [abs(float((points[2 * i + side] - u)[free] @ vectors[:, k])) / scales[k]
                     for side in (0, 1)]
                a = scan.measured_curvature(t[0], chis[2 * i] - chi_opt,
                                            t[1], chis[2 * i + 1] - chi_opt)
                if a is None:
                    continue
                a = min(max(a, 1.0 / MAX_WIDENING), MAX_WIDENING)
                scales[k] /= math.sqrt(a)
                if not 1.0 / SCAN_AGREEMENT ** 2 <= a <= SCAN_AGREEMENT ** 2:
                    still.append(k)
            todo = still
            if not todo:
                break
        if better is None:
            return u, converged, scan.covariance_of(scales, vectors), restarts
        restarts += 1
        u, converged = _least_squares(misfit, better, free, max_nfev)


def _start_points(start: NDArray[np.float64], fits: Sequence[FitParameter],
                  free: Sequence[int]) -> list[NDArray[np.float64]]:
    """Where the optimiser may start: the start values, and a quasi-random (Halton) design of
    ``STARTS_PER_PARAMETER`` points per fitted parameter over the region its prior allows (two
    prior standard deviations either side of the start; an undeclared one's whole range)."""
    from scipy.stats import qmc

    n = STARTS_PER_PARAMETER * len(free)
    unit = qmc.Halton(d=len(free), scramble=False).random(n + 1)[1:]  # without the corner 0
    points = [np.asarray(start, dtype=float)]
    for row in unit:
        point = np.asarray(start, dtype=float).copy()
        for value, j in zip(row, free, strict=True):
            reach = 2.0 * PRIOR_SD_UNIT if fits[j].declared else 1.0
            low, high = max(start[j] - reach, 0.0), min(start[j] + reach, 1.0)
            point[j] = low + value * (high - low)
        points.append(point)
    return points


def _best_of_starts(misfit: Misfit, start: NDArray[np.float64], fits: Sequence[FitParameter],
                    free: list[int], max_nfev: int) -> tuple[NDArray[np.float64], str]:
    """Bounded least squares from the start values and from the ``OPTIMISER_STARTS`` lowest
    other points of :func:`_start_points` (all evaluated in one batch): the misfit of kicks has
    valleys whose floors are not smooth (a contact sequence that changes), and one Gauss-Newton
    descent can end on the wrong side of a kink. Returns the lowest end, (u, message)."""
    points = _start_points(start, fits, free)
    chis = misfit.chi2_many(points)
    design = 1 + np.argsort(chis[1:])[:OPTIMISER_STARTS]  # points[0] is the start itself
    ends = [_least_squares(misfit, points[i], free, max_nfev) for i in (0, *design)]
    return min(ends, key=lambda end: misfit.chi2(end[0]))


def _embed(u: ArrayLike, free: list[int], step: NDArray[np.float64]) -> NDArray[np.float64]:
    point = np.asarray(u, dtype=float).copy()
    point[free] = np.clip(point[free] + step, 0.0, 1.0)
    return point


def _notes(fits: Sequence[FitParameter],
           why: Mapping[int, SetAside]) -> dict[int, tuple[str, str]]:
    """(status, note) of each parameter the selection set aside."""
    notes = {}
    for j, (status, partner, cos) in why.items():
        if status == 'unresolved':
            notes[j] = (status, 'the recorded kicks barely depend on it: held at its start value')
        else:
            notes[j] = (status, f'the kicks tell only a combination of it and '
                                f'{fits[cast(int, partner)].path} (their effects correlate at '
                                f'{cos:+.3f}): its interval spans what they leave open')
    return notes


def _least_squares(misfit: Misfit, start: ArrayLike, free: list[int],
                   max_nfev: int) -> tuple[NDArray[np.float64], str]:
    """Bounded least squares over the ``free`` scaled coordinates from ``start``;
    (u, message)."""
    from scipy.optimize import least_squares

    def full(x: NDArray[np.float64]) -> NDArray[np.float64]:
        v = np.asarray(start, dtype=float).copy()
        v[free] = x
        return v

    def fun(x: NDArray[np.float64]) -> NDArray[np.float64]:
        return misfit.residuals(full(x))

    def jac(x: NDArray[np.float64]) -> NDArray[np.float64]:
        return misfit.jacobian(full(x))[:, free]

    x0 = np.clip(np.asarray(start)[free], 1e-3, 1.0 - 1e-3)  # strictly inside the bounds
    sol = least_squares(fun, x0, jac=jac, bounds=(np.zeros(len(free)), np.ones(len(free))),
                        method='trf', x_scale=1.0, max_nfev=max_nfev, xtol=XTOL, ftol=FTOL)
    return full(sol.x), sol.message


def within_truth(result: IdentificationResult, truth: ParameterSet
                 ) -> list[tuple[str, float, tuple[float, ...], float, bool, str]]:
    """Per parameter: (path, value, interval, true value, inside, status) against ``truth`` (a
    ParameterSet); a held one counts as inside when the truth equals where it was held."""
    rows = []
    for p in result.parameters:
        true = truth.get(p.path)
        rows.append((p.path, p.value, p.interval, true, p.contains(true), p.status))
    return rows
