"""System identification: fit model parameters so that the continuous model reproduces kicks
recorded on one device.

What a device records is the commands it was sent (pulse programmes, voltages held) and its
measured surface normal (§6's magnetic sensor, with its noise), nothing more. Between kicks the
friction holds the sphere still, so every stretch of settled samples measures one resting
normal; their mean beats the sensor noise by the square root of their number. A kick is then an
observation: the programme, the resting normal before it and the resting normal after it.

The residual of a kick is the model's resting normal after the programme, started at rest at
the recorded normal before it, minus the recorded normal after it (its x and y components, in
rad). Each kick restarts from its own recorded start (multiple shooting): the errors do not
accumulate over a run, every kick is an independent simulation (one task on a process pool or
Dask), and the per-kick residuals allow a bootstrap over kicks.

The fit is :func:`scipy.optimize.least_squares` (trust-region reflective, bounded by the
parameters' ranges) in scaled coordinates (the logarithm of each value, mapped onto [0, 1] over
its range), with a finite-difference Jacobian whose simulations all run as one batch on the
engine. Every evaluated parameter vector and its residuals are appended to a checkpoint file:
the optimiser is deterministic, so a rerun retraces its path from the file and goes on where the
interrupted one stopped.

Before fitting, the Jacobian at the start and the measured sensor noise say what the recordings
can tell: a parameter whose expected uncertainty spans its whole range, or one almost perfectly
correlated with another (an unidentifiable pair), is held at its start value and reported as
such, never fitted blindly.
"""

import dataclasses
import hashlib
import json
import math
from functools import lru_cache
from pathlib import Path

import numpy as np
from threadpoolctl import threadpool_limits

from msg_defs.device import KICK_WINDOW_S
from sphere_sim.kicks.design import (
    KICK_RELAXATION,
    KICK_SAMPLE_PERIOD_S,
    cardan_of_normal,
    final_normal,
)
from sphere_sim.kicks.engine import engine_for
from sphere_sim.kicks.table_build import BLAS_THREADS_PER_KICK
from sphere_sim.model.assembly import assemble
from sphere_sim.model.initial_state import rest_state
from sphere_sim.model.programme import PulseProgramme
from sphere_sim.model.scene import load_scene

# The fit's tolerance, the live twin's (sphere_sim.twin.plants.LIVE_RTOL): a kick then ends
# within a few 1e-6 rad of the exact one, and that error jumps with the step-size sequence as a
# parameter moves; a finite-difference step (FD_STEP) of a parameter the kicks can tell moves
# the residuals by 1e-4 rad or more, so the jumps stay below 1 % of what the Jacobian reads
# (docs/identification.md).
FIT_RTOL = 3e-4
# Finite-difference step in the scaled coordinate ([0, 1] over the range, logarithmic).
FD_STEP = 0.01
# An undeclared parameter named for the fit is searched within this factor of its start value:
# a search bound of the identification, not a physical range (docs/identification.md).
UNDECLARED_FACTOR = 2.0
# What the recordings cannot tell: a parameter whose 2-sigma interval, with the ones fitted
# before it held, would cover more than this share of its scaled range; or one of a pair whose
# estimates would correlate beyond PAIR_CORRELATION_LIMIT.
UNRESOLVED_SHARE = 0.5
PAIR_CORRELATION_LIMIT = 0.95
# The optimiser stops when a step moves the scaled parameters by less than XTOL (a fraction of
# the standard errors that recordings of tens of kicks give, 0.03 and more) or the cost by less
# than FTOL of itself (a cost of 2 x 40 kicks noise-weighted residuals: 0.4, where one standard
# error of a parameter is worth 1).
XTOL = 1e-2
FTOL = 5e-3
# The curvature check may widen a direction's variance at most this many times.
MAX_WIDENING = 25.0
# The reported uncertainty: this many standard errors (about 95 % for a Gaussian estimate).
UNCERTAINTY_SIGMAS = 2.0
CHECKPOINT_VERSION = 1


class IdentificationError(ValueError):
    """Recordings or a request the identification cannot work with."""


# --- observations ---------------------------------------------------------------------------------

@dataclasses.dataclass(frozen=True)
class KickObservation:
    """One recorded kick: its programme and the resting normals around it.

    Attributes
    ----------
    time_s : float
        Start of the programme.
    times_s : ndarray, shape (k,)
    voltages_v : ndarray, shape (k, 4)
        The programme's zero-order-hold segments.
    normal_before, normal_after : ndarray, shape (3,)
        Means of the settled samples before and after the kick (unit vectors).
    samples_before, samples_after : int
        How many samples each mean is of.
    """

    time_s: float
    times_s: np.ndarray
    voltages_v: np.ndarray
    normal_before: np.ndarray
    normal_after: np.ndarray
    samples_before: int
    samples_after: int

    def programme(self):
        return PulseProgramme.from_segments(self.times_s, self.voltages_v)

    def to_dict(self):
        return {'time_s': self.time_s, 'times_s': np.asarray(self.times_s).tolist(),
                'voltages_v': np.asarray(self.voltages_v).tolist(),
                'normal_before': np.asarray(self.normal_before).tolist(),
                'normal_after': np.asarray(self.normal_after).tolist(),
                'samples_before': self.samples_before, 'samples_after': self.samples_after}


@dataclasses.dataclass(frozen=True)
class Observations:
    """The kicks of one or more recordings and the sensor noise measured in them."""

    kicks: tuple
    noise_std_rad: float  # per tangential axis, from the scatter within settled stretches
    dropped: int = 0  # programmes that could not be used (no settled samples around them)

    def digest(self):
        text = json.dumps([k.to_dict() for k in self.kicks], sort_keys=True)
        return hashlib.sha256(text.encode()).hexdigest()[:16]

    def residual_std_rad(self):
        """Expected standard deviation of each residual component from the sensor noise alone,
        per kick (the means before and after each carry it)."""
        return np.repeat([self.noise_std_rad * math.sqrt(1.0 / k.samples_before
                                                         + 1.0 / k.samples_after)
                          for k in self.kicks], 2)


def _unit_mean(normals):
    mean = np.mean(normals, axis=0)
    return mean / np.linalg.norm(mean)


def _tangential_scatter(normals, mean):
    """Squared tangential deviations (rad^2) of unit normals from their mean, summed, and
    the number of degrees of freedom they carry (two per sample, less two for the mean)."""
    d = normals - mean
    d -= np.outer(d @ mean, mean)
    return float(np.sum(d * d)), 2 * (len(normals) - 1)


def observations_from_samples(normal_t_s, normals, programmes, holds=(),
                              window_s=KICK_WINDOW_S, min_samples=2):
    """Cut a recording into kick observations.

    Parameters
    ----------
    normal_t_s : ndarray, shape (n,)
        Sample times of the measured normals.
    normals : ndarray, shape (n, 3)
    programmes : sequence of (start_s, times_s, voltages_v)
        The recorded pulse programmes, in any order.
    holds : sequence of (time_s, voltages_v)
        Recorded voltage commands. 0 V on every beam is the rest the kicks start from; a kick
        whose stretch before or after contains another hold is dropped (the model starts each
        kick at rest with the beams unpowered).
    window_s : float
        A programme's effect counts as over this long after its start (or at its end, if
        later); samples from then until the next programme are settled.
    min_samples : int
        Fewest settled samples before and after a kick for it to count.

    Raises
    ------
    IdentificationError
        When no kick has settled samples on both sides.
    """
    t = np.asarray(normal_t_s, dtype=float)
    n = np.asarray(normals, dtype=float)
    progs = sorted(((float(s), np.asarray(ts, dtype=float), np.asarray(vs, dtype=float))
                    for s, ts, vs in programmes), key=lambda p: p[0])
    powered = [float(ht) for ht, volts in holds if np.any(np.asarray(volts) != 0.0)]
    kicks, dropped, ss, dof = [], 0, 0.0, 0
    for i, (start, times, volts) in enumerate(progs):
        settled_from = start + max(window_s, float(times[-1]))
        prev_end = (progs[i - 1][0] + max(window_s, float(progs[i - 1][1][-1]))
                    if i else -math.inf)
        next_start = progs[i + 1][0] if i + 1 < len(progs) else math.inf
        before = (t >= prev_end - 1e-9) & (t < start - 1e-9)
        after = (t >= settled_from - 1e-9) & (t < next_start - 1e-9)
        interrupted = any(prev_end - 1e-9 <= h < next_start for h in powered)
        if before.sum() < min_samples or after.sum() < min_samples or interrupted:
            dropped += 1
            continue
        n_before, n_after = _unit_mean(n[before]), _unit_mean(n[after])
        kicks.append(KickObservation(start, times, volts, n_before, n_after,
                                     int(before.sum()), int(after.sum())))
        # Each settled stretch counted once for the noise (the one after each kick, and the
        # one before the first).
        for mask, mean in ([(before, n_before)] if not kicks[:-1] else []) + [(after, n_after)]:
            s, d = _tangential_scatter(n[mask], mean)
            ss, dof = ss + s, dof + d
    if not kicks:
        raise IdentificationError('no kick with settled samples before and after it: the '
                                  'recording needs pauses between programmes')
    noise = math.sqrt(ss / dof) if dof else 0.0  # per axis
    return Observations(tuple(kicks), noise, dropped)


def merge_observations(parts):
    """Observations of several recordings as one set (noise pooled by kick count)."""
    kicks = tuple(k for part in parts for k in part.kicks)
    weights = [len(part.kicks) for part in parts]
    noise = math.sqrt(np.average([p.noise_std_rad ** 2 for p in parts], weights=weights))
    return Observations(kicks, noise, sum(p.dropped for p in parts))


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
    tied: tuple = ()
    declared: bool = True

    def __post_init__(self):
        if not (self.low * self.high > 0 and self.low < self.high):
            raise IdentificationError(f'{self.path}: the range [{self.low:g}, {self.high:g}] '
                                      'must lie on one side of zero')

    @property
    def _log_bounds(self):
        a, b = math.log(abs(self.low)), math.log(abs(self.high))
        return min(a, b), max(a, b)

    @property
    def sign(self):
        return 1.0 if self.low > 0 else -1.0

    def to_unit(self, value):
        lo, hi = self._log_bounds
        return (math.log(abs(value)) - lo) / (hi - lo)

    def from_unit(self, u):
        lo, hi = self._log_bounds
        return self.sign * math.exp(lo + float(u) * (hi - lo))

    def value_sigma(self, value, sigma_unit):
        """A standard error in the scaled coordinate as one of the value (at ``value``)."""
        lo, hi = self._log_bounds
        return abs(value) * (hi - lo) * sigma_unit

    def assign(self, value):
        return {path: value for path in (self.path, *self.tied)}


def fit_parameters(params, names=None):
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


def params_at(params, fits, values):
    """``params`` with each fitted path (and its ties) set to ``values``."""
    assigned = {}
    for fit, value in zip(fits, values, strict=True):
        assigned.update(fit.assign(float(value)))
    return params.replace(**assigned)


# --- one kick, one task ---------------------------------------------------------------------------

@lru_cache(maxsize=8)
def _model(params):
    return assemble(load_scene('rest'), params)


def kick_end_normal(params, kick, rtol=FIT_RTOL):
    """The model's resting normal after ``kick``'s programme, from rest at its recorded start."""
    with threadpool_limits(limits=BLAS_THREADS_PER_KICK):
        model = _model(params)
        x_rest = rest_state(model, cardan_of_normal(kick.normal_before),
                            relaxation=KICK_RELAXATION)
        window = max(KICK_WINDOW_S, float(kick.times_s[-1]))
        return np.asarray(final_normal(model, kick.normal_before, kick.programme(), window,
                                       rtol, x_rest,
                                       sample_period_s=max(window, KICK_SAMPLE_PERIOD_S)),
                          dtype=float)


def _kick_task(task):
    params, kick, rtol = task
    return kick_end_normal(params, kick, rtol)


def kick_residuals(observations, ends):
    """Residual vector (2 per kick: x and y of model minus recorded resting normal, rad)."""
    return np.concatenate([(np.asarray(end) - k.normal_after)[:2]
                           for k, end in zip(observations.kicks, ends, strict=True)])


# --- evaluations, cached and checkpointed ---------------------------------------------------------

class Evaluator:
    """Residuals at scaled parameter vectors, each simulated once (in batches on an engine)
    and appended to a checkpoint file that a rerun reads back."""

    def __init__(self, params, observations, fits, engine, rtol=FIT_RTOL, checkpoint=None,
                 progress=None):
        self.params, self.obs, self.fits = params, observations, fits
        self.engine, self.rtol, self.progress = engine, rtol, progress
        self.cache = {}
        self.simulated = 0
        self._written = False  # this run has started its own checkpoint file
        self.checkpoint = Path(checkpoint) if checkpoint is not None else None
        self.digest = self._digest()
        self.resumed = self._read_checkpoint()

    def _digest(self):
        text = json.dumps({'version': CHECKPOINT_VERSION, 'params': self.params.digest(),
                           'observations': self.obs.digest(), 'rtol': self.rtol,
                           'fits': [dataclasses.asdict(f) for f in self.fits]},
                          sort_keys=True, default=list)
        return hashlib.sha256(text.encode()).hexdigest()[:16]

    @staticmethod
    def key(u):
        return tuple(float(v).hex() for v in np.asarray(u, dtype=float))

    def _read_checkpoint(self):
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

    def _append(self, entries):
        if self.checkpoint is None:
            return
        fresh = not self.checkpoint.exists() or (not self.resumed and not self._written)
        with open(self.checkpoint, 'w' if fresh else 'a') as stream:
            if fresh:
                stream.write(json.dumps({'digest': self.digest}) + '\n')
            for key, r in entries:
                stream.write(json.dumps({'u': list(key), 'r': r.tolist()}) + '\n')
        self._written = True

    def values(self, u):
        return [fit.from_unit(v) for fit, v in zip(self.fits, u, strict=True)]

    def many(self, points):
        """Residual vectors at each scaled point; the uncached ones simulated in one batch."""
        keys = [self.key(u) for u in points]
        todo = list(dict.fromkeys(k for k in keys if k not in self.cache))
        if todo:
            tasks, owners = [], []
            for key in todo:
                p = params_at(self.params, self.fits,
                              self.values([float.fromhex(v) for v in key]))
                tasks += [(p, kick, self.rtol) for kick in self.obs.kicks]
                owners.append(key)
            ends = self.engine(_kick_task, tasks)
            self.simulated += len(tasks)
            n = len(self.obs.kicks)
            entries = []
            for i, key in enumerate(owners):
                r = kick_residuals(self.obs, ends[i * n:(i + 1) * n])
                self.cache[key] = r
                entries.append((key, r))
            self._append(entries)
        if self.progress is not None:
            self.progress(self)
        return [self.cache[k] for k in keys]

    def __call__(self, u):
        return self.many([u])[0]

    def jacobian(self, u, step=FD_STEP):
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

def covariance(jac, noise_std):
    """(JᵀWJ)⁻¹ of residuals with standard deviations ``noise_std`` (pseudo-inverse)."""
    jw = jac / np.asarray(noise_std)[:, None]
    return np.linalg.pinv(jw.T @ jw)


def select_identifiable(jac, noise_std):
    """Which parameters the recordings can tell, and why each other one is held.

    Orthogonal selection on the noise-weighted Jacobian: take the parameter the residuals are
    most sensitive to, remove its direction from the others, and go on while the next one's
    remaining sensitivity still pins it to ``UNRESOLVED_SHARE`` of its range at
    ``UNCERTAINTY_SIGMAS``; then, while two selected ones would have estimates correlated
    beyond ``PAIR_CORRELATION_LIMIT``, hold the less sensitive of them. A parameter left out is
    *unresolved* when even alone it could not be pinned so, and otherwise *entangled*: its
    effect on the kicks is (nearly) a combination of those selected, and its partner is the
    selected one whose effect it resembles most.

    Returns
    -------
    selected : list of int
    held : dict of int -> (status, partner index or None, cosine of their effects)
    """
    jw = jac / np.asarray(noise_std)[:, None]
    p = jw.shape[1]
    limit = UNCERTAINTY_SIGMAS / UNRESOLVED_SHARE
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
    # the kicks trade one for the other; the less sensitive one is held.
    while len(selected) > 1:
        cov = np.linalg.pinv(jw[:, selected].T @ jw[:, selected])
        sd = np.sqrt(np.diag(cov))
        corr = np.abs(cov / np.outer(sd, sd)) - np.eye(len(selected))
        a, b = np.unravel_index(np.argmax(corr), corr.shape)
        if corr[a, b] <= PAIR_CORRELATION_LIMIT:
            break
        weak = selected[a] if alone[selected[a]] < alone[selected[b]] else selected[b]
        selected.remove(weak)
        remaining.append(weak)
    held = {}
    for j in remaining:
        if alone[j] < limit or not selected:
            held[j] = ('unresolved', None, 0.0)
            continue
        cos = [float(jw[:, j] @ jw[:, k] / (alone[j] * alone[k])) for k in selected]
        k = int(np.argmax(np.abs(cos)))
        held[j] = ('entangled', selected[k], cos[k])
    return selected, held


# --- the fit --------------------------------------------------------------------------------------

@dataclasses.dataclass
class FittedParameter:
    path: str
    start: float
    value: float
    uncertainty: float  # UNCERTAINTY_SIGMAS standard errors (nan where held)
    low: float
    high: float
    declared: bool
    status: str  # 'fitted', 'unresolved' (held), 'entangled' (held: unidentifiable with another)
    note: str = ''
    tied: tuple = ()

    def to_dict(self):
        return {'path': self.path, 'tied': list(self.tied), 'start': self.start,
                'value': self.value,
                'uncertainty': None if math.isnan(self.uncertainty) else self.uncertainty,
                'range': [self.low, self.high], 'declared_range': self.declared,
                'status': self.status, 'note': self.note}


@dataclasses.dataclass
class IdentificationResult:
    parameters: list  # FittedParameter, in the order asked
    vectors_before: np.ndarray  # (k, 2): x and y of model minus recorded, at the start values
    vectors_after: np.ndarray  # (k, 2): the same at the fitted values
    noise_std_rad: float
    correlation: np.ndarray  # among the fitted ones, at the optimum
    evaluations: int
    simulated_kicks: int
    resumed_evaluations: int
    converged: str
    cost_ratio: float  # sum of squares after over what the sensor noise alone explains

    @property
    def residuals_before(self):
        """Per kick: angle (rad) between the model's and the recorded resting normal."""
        return np.hypot(*self.vectors_before.T)

    @property
    def residuals_after(self):
        return np.hypot(*self.vectors_after.T)

    def fitted(self):
        return [p for p in self.parameters if p.status == 'fitted']

    def values(self):
        return {p.path: p.value for p in self.parameters}


def identify(params, observations, fits, workers=1, scheduler=None, rtol=FIT_RTOL,
             checkpoint=None, progress=None, max_nfev=30):
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
        Most residual evaluations of the optimiser (each one a batch of kicks).
    """
    fits = list(fits)
    if not fits:
        raise IdentificationError('nothing to fit: name parameters with --fit, or use a '
                                  'parameter set that declares some uncertain')
    if len(observations.kicks) * 2 <= len(fits):
        raise IdentificationError(f'{len(observations.kicks)} kicks cannot fit {len(fits)} '
                                  'parameters: record more')
    noise = observations.residual_std_rad()
    if observations.noise_std_rad == 0.0:
        noise = np.full_like(noise, 1e-9)  # noiseless recordings: the integrator's own error
    with engine_for(workers, scheduler) as engine:
        ev = Evaluator(params, observations, fits, engine, rtol, checkpoint, progress)
        start = np.array([min(max(f.to_unit(params.get(f.path)), 0.0), 1.0) for f in fits])
        j0 = ev.jacobian(start)
        r0 = ev(start)
        held = _held(fits, select_identifiable(j0, noise)[1])
        free = [j for j in range(len(fits)) if j not in held]
        u, converged, cov_free = start.copy(), 'nothing fitted', np.zeros((0, 0))
        if free:
            u, converged = _least_squares(ev, start, free, noise, max_nfev)
            cov_free = _secant_checked(ev, u, free, covariance(ev.jacobian(u)[:, free], noise),
                                       noise)
        r1 = ev(u)
    chi2 = float(np.sum((r1 / noise) ** 2)) / max(1, r1.size - len(free))
    # The sensor noise sets the scale; a fit worse than it explains widens the errors too.
    scale = max(1.0, chi2)
    results = []
    for j, fit in enumerate(fits):
        start_value = params.get(fit.path)
        if j in held:
            results.append(FittedParameter(fit.path, start_value, start_value, math.nan,
                                           fit.low, fit.high, fit.declared, *held[j], fit.tied))
            continue
        k = free.index(j)
        value = fit.from_unit(u[j])
        sigma_u = math.sqrt(max(cov_free[k, k], 0.0) * scale)
        results.append(FittedParameter(
            fit.path, start_value, value, UNCERTAINTY_SIGMAS * fit.value_sigma(value, sigma_u),
            fit.low, fit.high, fit.declared, 'fitted', '', fit.tied))
    sig = np.sqrt(np.clip(np.diag(cov_free), 1e-300, None))
    corr = cov_free / np.outer(sig, sig) if free else cov_free
    return IdentificationResult(results, r0.reshape(-1, 2), r1.reshape(-1, 2),
                                observations.noise_std_rad, corr, len(ev.cache), ev.simulated,
                                ev.resumed, converged, chi2)


def _secant_checked(ev, u, free, cov, noise):
    """The covariance with the curvature along each of its principal directions measured over
    the interval it reports (two standard errors either way) instead of the Jacobian's 1 %
    step: where the sum of squares rises less there than the quadratic model says (a valley
    that bends, a kink), the variance along that direction grows by the ratio, at most
    ``MAX_WIDENING`` times."""
    values, vectors = np.linalg.eigh(cov)
    chi_opt = float(np.sum((ev(u) / noise) ** 2))
    points, steps = [], []
    for k in range(values.size):
        for sign in (1.0, -1.0):
            step = np.zeros(u.size)
            step[free] = sign * UNCERTAINTY_SIGMAS * math.sqrt(max(values[k], 0.0)) * \
                vectors[:, k]
            point = np.clip(u + step, 0.0, 1.0)
            points.append(point)
            steps.append((point - u)[free])
    chis = [float(np.sum((r / noise) ** 2)) for r in ev.many(points)]
    inverse = np.linalg.pinv(cov)
    widened = cov.copy()
    for k in range(values.size):
        ratios = []
        for i in (2 * k, 2 * k + 1):
            predicted = float(steps[i] @ inverse @ steps[i])
            rise = chis[i] - chi_opt
            if predicted > 0.0:
                ratios.append(MAX_WIDENING if rise <= predicted / MAX_WIDENING
                              else predicted / rise)
        ratio = max(ratios, default=1.0)
        if ratio > 1.0:
            widened += (ratio - 1.0) * values[k] * np.outer(vectors[:, k], vectors[:, k])
    return widened


def _held(fits, why):
    """(status, note) of each parameter the selection holds."""
    held = {}
    for j, (status, partner, cos) in why.items():
        if status == 'unresolved':
            held[j] = (status, 'the recorded kicks barely depend on it: held at its start value')
        else:
            held[j] = (status, f'cannot be told apart from {fits[partner].path} by these kicks '
                               f'(their effects correlate at {cos:+.3f}): held at its start '
                               f'value, {fits[partner].path} fitted for both')
    return held


def _least_squares(ev, start, free, noise, max_nfev):
    """Bounded least squares over the ``free`` scaled coordinates; (u, message)."""
    from scipy.optimize import least_squares

    def full(x):
        v = start.copy()
        v[free] = x
        return v

    def fun(x):
        return ev(full(x)) / noise

    def jac(x):
        return ev.jacobian(full(x))[:, free] / noise[:, None]

    x0 = np.clip(start[free], 1e-3, 1.0 - 1e-3)  # strictly inside the bounds
    sol = least_squares(fun, x0, jac=jac, bounds=(np.zeros(len(free)), np.ones(len(free))),
                        method='trf', x_scale=1.0, max_nfev=max_nfev, xtol=XTOL, ftol=FTOL)
    return full(sol.x), sol.message


def within_truth(result, truth):
    """Per fitted parameter: (path, value, uncertainty, true value, inside) against ``truth``
    (a ParameterSet); held ones count as inside when the truth equals where they were held."""
    rows = []
    for p in result.parameters:
        true = truth.get(p.path)
        if p.status == 'fitted':
            inside = abs(p.value - true) <= p.uncertainty
        else:
            inside = math.isclose(true, p.value, rel_tol=1e-12)
        rows.append((p.path, p.value, p.uncertainty, true, inside, p.status))
    return rows
