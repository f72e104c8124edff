"""One fit of every kind of observation a device's recordings hold: the kicks' landings and the
experiment protocol's thresholds, in one misfit; a multi-start over the declared ranges; each
parameter's 95 % profile-likelihood interval; and a parameter the recordings leave open
reported as undetermined, with its range.

The two kinds tell different things (docs/identification.md, "An experiment protocol"): a
threshold moves smoothly with the beams' stiffness, gap and damping, a kick's landing tells the
friction once the beams are pinned, and moves in steps as the pull-in's parameters change.
Fitted together, the thresholds hold the pull-in's parameters where the kicks alone trade them
along a valley, and the kicks decide what the thresholds do not see.

With both kinds, a multi-start runs on the thresholds alone (their misfit is smooth where the
kicks' has steps) over the parameters they see
(:func:`~sphere_sim.fitting.profile_fit.seen_coordinates`), a second on the kicks over the
others with those held at the first's optimum; from there, from points drawn over the
thresholds' 95 % region about it (:func:`~sphere_sim.fitting.profile_fit.region_draws`: which
kick lands on which branch changes within it) or from the start values, whichever the joint
misfit puts lowest, the joint fit goes on by Levenberg-Marquardt on a difference Jacobian (the
searches have brought it near), and the profiles are read about its end.

The misfit is a plain sum of squares of residuals in units of their standard deviations: the
kicks' residuals whitened by the sensor noise (with the restart's error,
:meth:`~sphere_sim.fitting.observations.Observations.whitener`), and each threshold's
(model - bracket middle) / :attr:`~sphere_sim.fitting.thresholds.ThresholdObservation.std_v`,
and a slow ramp's the same of its jump (:class:`~sphere_sim.fitting.ramps.RampObservation`).
No prior: what the intervals say is what the recordings say. Every parameter vector is
simulated once, kicks and thresholds as one batch of tasks on the engine, and checkpointed
(:class:`~sphere_sim.fitting.identification.Evaluator`), so an interrupted fit resumes.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from sphere_sim.fitting.identification import (
    Evaluator,
    FitParameter,
    undetermined_kicks,
)
from sphere_sim.fitting.observations import IdentificationError, Observations
from sphere_sim.fitting.profile_fit import (
    ProfileFit,
    ProfileInterval,
    fit_profiles,
    reaches_the_noise,
    region_draws,
    search_coordinates,
    seen_coordinates,
)
from sphere_sim.fitting.ramps import PullInObservation
from sphere_sim.fitting.thresholds import ThresholdObservation, non_monotone, switches_text
from sphere_sim.integrate.tolerances import FIT_RTOL
from sphere_sim.kicks.engine import SerialEngine, engine_for
from sphere_sim.model.parameters import ParameterSet

# Latin-hypercube starts per fitted parameter, and descents from the lowest of them (the start
# values are a further start): over the declared ranges a threshold misfit is smooth but far
# from quadratic (its residuals run to hundreds of standard deviations), so a few descents
# from spread points find its basin where one from the start values may stall at a bound.
STARTS_PER_PARAMETER = 3
DESCENTS = 2
# Starts of the joint fit drawn from the thresholds' linearised posterior, per parameter they
# see (profile_fit.region_draws), beside their optimum: each costs one joint evaluation, and
# they are evaluated as one batch.
REGION_DRAWS_PER_PARAMETER = 4
# The cost limit's default: distinct parameter vectors simulated (each one every kick and every
# threshold: some 0.1-0.3 s per kick on one core, and per threshold 0.3 s where its cell is
# predicted from the points near (thresholds.predicted_thresholds_v), 0.6 s from the recorded
# bracket, up to 1.7 s where the model's threshold lies volts off it).
MAX_EVALUATIONS = 300


@dataclasses.dataclass(frozen=True)
class ProfileEstimate:
    """One fitted parameter: its value, its 95 % profile interval, its declared range, and
    whether the recordings determine it (``note`` says why not)."""

    path: str
    value: float
    low: float  # the 95 % profile interval (values, not scaled)
    high: float
    range_low: float  # the declared range (or search bound)
    range_high: float
    determined: bool
    note: str

    def contains(self, value: float) -> bool:
        return min(self.low, self.high) <= value <= max(self.low, self.high)


@dataclasses.dataclass(frozen=True)
class JointFitResult:
    estimates: tuple[ProfileEstimate, ...]
    chi2: float  # at the optimum: kicks' and thresholds' together
    kicks_chi2: float  # the kicks' whitened share of it, over 2 x len(kicks.kicks) residuals
    kicks: Observations  # the kicks fitted (those the model determines)
    undetermined: tuple[int, ...]  # the kicks left out, indices into those given
    thresholds: tuple[PullInObservation, ...]  # the searches', then the ramps'
    threshold_residuals: NDArray[np.float64]  # at the optimum, in standard deviations
    model_thresholds_v: NDArray[np.float64]  # at the optimum
    kick_vectors_start: NDArray[np.float64]  # (k, 2) model minus recorded, rad, at the start
    kick_vectors_fitted: NDArray[np.float64]  # the same at the optimum
    evaluations: int  # of the misfit the intervals are read from
    profile: ProfileFit
    # of the thresholds alone, searched first when kicks and thresholds are fitted together
    threshold_search_evaluations: int = 0
    # of the joint misfit, searching the parameters the thresholds do not see (in evaluations)
    kick_search_evaluations: int = 0
    # thresholds left out, whose pulses at the start values do not rise once with the
    # amplitude (thresholds.non_monotone), each with where its outcome switches
    non_monotone: tuple[tuple[ThresholdObservation, str], ...] = ()
    # with kicks and thresholds both: the parameters the thresholds see, searched on them alone
    # (the others on the kicks)
    seen_by_thresholds: tuple[str, ...] = ()
    # with kicks and thresholds both: the joint fit's starts drawn over the thresholds' region
    region_draws: int = 0

    @property
    def threshold_chi2(self) -> float:
        return float(np.sum(self.threshold_residuals ** 2))


class JointMisfit:
    """Residuals in standard deviations at a scaled parameter vector (each parameter's
    logarithm mapped onto [0, 1] over its range): the kicks' whitened, then the thresholds'."""

    def __init__(self, evaluator: Evaluator) -> None:
        self.ev = evaluator
        self.kick_rows = 2 * len(evaluator.obs.kicks)
        self.whitener = (evaluator.obs.whitener() if self.kick_rows
                         else np.zeros((0, 0)))
        self.middles_v = np.array([t.middle_v for t in evaluator.thresholds])
        self.stds_v = np.array([t.std_v for t in evaluator.thresholds])

    def kick_vectors(self, u: ArrayLike) -> NDArray[np.float64]:
        """(k, 2): each kick's model minus recorded resting normal, x and y (rad)."""
        return self.ev(u)[:self.kick_rows].reshape(-1, 2)

    def thresholds_v(self, u: ArrayLike) -> NDArray[np.float64]:
        return self.ev(u)[self.kick_rows:]

    def __call__(self, u: ArrayLike) -> NDArray[np.float64]:
        return self._whitened(self.ev(u))

    def many(self, points: Sequence[ArrayLike]) -> list[NDArray[np.float64]]:
        """The residuals at each point, simulated as one batch on the engine."""
        return [self._whitened(r) for r in self.ev.many(points)]

    def _whitened(self, r: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.concatenate([self.whitener @ r[:self.kick_rows],
                               (r[self.kick_rows:] - self.middles_v) / self.stds_v])


def fit_jointly(params: ParameterSet, fits: Sequence[FitParameter],
                kicks: Observations | None, thresholds: Sequence[PullInObservation],
                workers: int | SerialEngine = 1, scheduler: str | None = None,
                checkpoint: str | Path | None = None,
                progress: Callable[[Evaluator], object] | None = None,
                max_evaluations: int = MAX_EVALUATIONS, seed: int = 0,
                starts_per_parameter: int = STARTS_PER_PARAMETER, descents: int = DESCENTS,
                rtol: float = FIT_RTOL) -> JointFitResult:
    """Fit ``fits`` (starting from their values in ``params``) to recorded kicks and
    thresholds together.

    Parameters
    ----------
    kicks : Observations or None
        The recorded kicks (None: thresholds alone). A kick whose end the model at the start
        values does not determine is left out first
        (:func:`~sphere_sim.fitting.identification.undetermined_kicks`).
    thresholds : sequence of ThresholdObservation or RampObservation
        The protocol's recorded brackets and ramps (may be empty: kicks alone). A bracket whose
        pulses at the start values do not rise once with the amplitude around it is left out
        first (:func:`~sphere_sim.fitting.thresholds.non_monotone`).
    workers, scheduler
        Local processes, or a started engine (left open), or a Dask scheduler's address.
    checkpoint : path, optional
        Every evaluation is appended here; a rerun with the same inputs reads them back.
    max_evaluations : int
        Distinct parameter vectors simulated, search and profiles together; a profile the
        limit stops is reported undetermined. With kicks and thresholds both, the search on
        the thresholds alone that comes first has a limit of its own, as large; the search of
        the kicks over the parameters the thresholds do not see counts in the joint limit.
    """
    fits = list(fits)
    if not fits:
        raise IdentificationError('nothing to fit: name parameters with --fit, or use a '
                                  'parameter set that declares some uncertain')
    kicks = kicks if kicks is not None else Observations((), 0.0)
    if not kicks.kicks and not thresholds:
        raise IdentificationError('nothing to fit to: no kick and no threshold')
    start = np.array([min(max(f.to_unit(params.get(f.path)), 0.0), 1.0) for f in fits])
    with engine_for(workers, scheduler) as engine:
        undetermined = undetermined_kicks(params, kicks, engine, rtol) if kicks.kicks else ()
        kicks = kicks.without(undetermined)
        searches = [t for t in thresholds if isinstance(t, ThresholdObservation)]
        scans = non_monotone(params, searches, engine, rtol) if searches else {}
        left_out = tuple((t, switches_text(scans[i])) for i, t in enumerate(searches)
                         if i in scans)
        dropped = {id(t) for t, _ in left_out}
        thresholds = [t for t in thresholds if id(t) not in dropped]
        if not kicks.kicks and not thresholds:
            raise IdentificationError(
                'nothing left to fit to: every threshold\'s pulses switch more than once '
                'around it, and there is no kick')
        both = bool(kicks.kicks) and bool(thresholds)
        # With both, the search on the thresholds alone comes first (below), and the thresholds
        # it searched predict where the joint fit's searches start.
        alone = Evaluator(params, Observations((), 0.0), fits, engine, rtol,
                          None if checkpoint is None else thresholds_checkpoint(checkpoint),
                          progress, thresholds) if both else None
        evaluator = Evaluator(params, kicks, fits, engine, rtol, checkpoint, progress,
                              thresholds, predicted_from=() if alone is None else (alone,))
        misfit = JointMisfit(evaluator)
        searched = used = 0
        seen: tuple[int, ...] = ()
        draws: list[NDArray[np.float64]] = []
        if alone is not None:
            # The thresholds' misfit is smooth in the beams' parameters where the kicks'
            # landings move in steps (paper_b: a multi-start of the two together ended at a sum
            # of squares of 198 against the truth's 34). Its basin is found on the thresholds
            # alone, over the parameters they see; those they do not see (the friction's) are
            # then searched on the kicks with the beams' held there, and the joint fit goes on
            # from the lower of that point and the start values. A multi-start of
            # the thresholds over every parameter left those they do not see wherever its
            # best start fell (the shipped example's six: a sum of squares of 613 against the
            # truth's 36, one of six within its interval).
            thresholds_misfit = JointMisfit(alone)
            seen = seen_coordinates(thresholds_misfit, start)
            # Descents by least squares. The polish's rounds took 43 evaluations here instead
            # of 79 on the shipped example's three, but on its six they ended elsewhere along
            # the thresholds' valley (the static coefficient 0.44, truth 0.3, at a sum of
            # squares of 5.2 over them), where the kicks' misfit is 290 above the truth's.
            u_thresholds, _, _ = search_coordinates(
                thresholds_misfit, start, seen, starts_per_parameter, descents, seed,
                max_evaluations)
            unseen = [j for j in range(len(fits)) if j not in seen]
            # Only the starts on the kicks, and the polish below descends from the lowest:
            # on the shipped example's six, two descents over the bristle stiffness alone
            # ended where the starts and the polish end (a sum of squares of 35.57, the same
            # values), and the starts cost 4 evaluations.
            u_kicks, _, used = search_coordinates(
                misfit, u_thresholds, unseen, starts_per_parameter, 0, seed, max_evaluations)
            # Which kick lands on which branch changes within the thresholds' own 95 % region
            # (the shipped example's three: polished from the thresholds' optimum, the joint
            # fit ended at a sum of squares of 70.7, where a profile found 34.8 at 0.005 of
            # k_z's range away): starts drawn from that region, the polish from the lowest.
            draws = region_draws(thresholds_misfit, u_kicks, seen,
                                 REGION_DRAWS_PER_PARAMETER * len(seen), seed, max_evaluations)
            searched = len(alone.cache)
            fit = fit_profiles(misfit, len(fits), start, starts=0, descents=0, seed=seed,
                               max_evaluations=max(max_evaluations - used, 1),
                               extra_starts=[u_kicks, *draws], polish=True)
        else:
            fit = fit_profiles(misfit, len(fits), start,
                               starts=starts_per_parameter * len(fits), descents=descents,
                               seed=seed, max_evaluations=max_evaluations)
        r = misfit(fit.u)
        above_noise = None if reaches_the_noise(fit.chi2, r.size, len(fits)) else (
            f'the fit does not reach the noise (a sum of squares of {fit.chi2:.1f} over '
            f'{r.size} residuals), so its profile bounds nothing')
        result = JointFitResult(
            estimates=tuple(_estimate(fp, fit.u, interval, above_noise)
                            for fp, interval in zip(fits, fit.intervals, strict=True)),
            chi2=fit.chi2, kicks_chi2=float(np.sum(r[:misfit.kick_rows] ** 2)), kicks=kicks,
            undetermined=tuple(undetermined), thresholds=tuple(thresholds),
            threshold_residuals=r[misfit.kick_rows:],
            model_thresholds_v=misfit.thresholds_v(fit.u),
            kick_vectors_start=misfit.kick_vectors(start),
            kick_vectors_fitted=misfit.kick_vectors(fit.u),
            evaluations=len(evaluator.cache), profile=fit,
            threshold_search_evaluations=searched, kick_search_evaluations=used,
            non_monotone=left_out,
            seen_by_thresholds=tuple(fits[j].path for j in seen), region_draws=len(draws))
    return result


def thresholds_checkpoint(checkpoint: str | Path) -> Path:
    """Where the search on the thresholds alone checkpoints, beside the joint fit's file."""
    return Path(checkpoint).with_suffix('.thresholds.jsonl')


def _estimate(fp: FitParameter, u: NDArray[np.float64], interval: ProfileInterval,
              above_noise: str | None) -> ProfileEstimate:
    """``above_noise``: why the fit's sum of squares is not one the noise gives
    (:func:`~sphere_sim.fitting.profile_fit.reaches_the_noise`), or None; if it is not, no
    interval is called determined, however narrow."""
    ends = sorted((fp.from_unit(interval.low_u), fp.from_unit(interval.high_u)))
    determined = interval.determined and above_noise is None
    if above_noise is not None:
        note = above_noise
    elif interval.determined:
        note = f'95 % interval {interval.width_u:.3f} of the scaled range'
    elif not interval.complete:
        note = 'the cost limit stopped its profile'
    elif interval.low_at_bound or interval.high_at_bound:
        note = 'its profile reaches a bound of the range'
    else:
        note = f'its 95 % interval spans {interval.width_u:.2f} of the scaled range'
    return ProfileEstimate(fp.path, fp.from_unit(float(u[interval.index])), ends[0], ends[1],
                           fp.low, fp.high, determined, note)
