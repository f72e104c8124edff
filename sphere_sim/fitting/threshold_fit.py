"""A fit of the pull-in's parameters to the protocol's recorded thresholds: a multi-start over
the declared ranges, then each parameter's 95 % profile-likelihood interval, and a parameter
the thresholds do not pin reported as undetermined with its range (issue 48, item 2, for the
thresholds; the kicks' part is identification's, :mod:`sphere_sim.fitting.identification`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from sphere_sim.fitting.identification import FitParameter
from sphere_sim.fitting.profile_fit import ProfileFit, fit_profiles
from sphere_sim.fitting.thresholds import (
    MODEL_RESOLUTION_V,
    ThresholdMisfit,
    ThresholdObservation,
)
from sphere_sim.integrate.tolerances import FIT_RTOL
from sphere_sim.model.parameters import ParameterSet

# Latin-hypercube starts per fitted parameter, and descents from the lowest of them (the start
# values are a further start): over the declared ranges a threshold misfit is smooth but far
# from quadratic (its residuals run to hundreds of standard deviations), so a few descents
# from spread points find its basin where one from the start values may stall at a bound.
STARTS_PER_PARAMETER = 3
DESCENTS = 2
# The cost limit's default: distinct parameter vectors simulated (each one every threshold,
# some 0.6-1 s per threshold on one core).
MAX_EVALUATIONS = 300


@dataclasses.dataclass(frozen=True)
class ThresholdEstimate:
    """One fitted parameter: its value, its 95 % profile interval, its declared range, and
    whether the thresholds determine it (``note`` says why not)."""

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
class ThresholdFitResult:
    estimates: tuple[ThresholdEstimate, ...]
    chi2: float  # at the optimum, over len(residuals) thresholds
    residuals: NDArray[np.float64]  # at the optimum, in standard deviations
    model_thresholds_v: NDArray[np.float64]  # at the optimum
    evaluations: int
    profile: ProfileFit


def fit_thresholds(params: ParameterSet, fits: Sequence[FitParameter],
                   observations: Sequence[ThresholdObservation],
                   max_evaluations: int = MAX_EVALUATIONS, seed: int = 0,
                   starts_per_parameter: int = STARTS_PER_PARAMETER,
                   descents: int = DESCENTS,
                   resolution_v: float = MODEL_RESOLUTION_V,
                   rtol: float = FIT_RTOL) -> ThresholdFitResult:
    """Fit ``fits`` (starting from their values in ``params``) to the recorded thresholds.

    ``max_evaluations`` bounds the parameter vectors simulated, search and profiles together;
    a profile it cuts short is reported undetermined. The search evaluates the start values
    and ``starts_per_parameter`` Latin-hypercube points per parameter over the ranges, and
    descends from the ``descents`` lowest."""
    misfit = ThresholdMisfit(params, fits, observations, resolution_v, rtol)
    start = np.array([min(max(f.to_unit(params.get(f.path)), 0.0), 1.0) for f in fits])
    fit = fit_profiles(misfit, len(fits), start, starts=starts_per_parameter * len(fits),
                       descents=descents, seed=seed, max_evaluations=max_evaluations)
    estimates = []
    for fp, interval in zip(fits, fit.intervals, strict=True):
        ends = sorted((fp.from_unit(interval.low_u), fp.from_unit(interval.high_u)))
        if interval.determined:
            note = f'95 % interval {interval.width_u:.3f} of the scaled range'
        elif not interval.complete:
            note = 'the cost limit stopped its profile'
        elif interval.low_at_bound or interval.high_at_bound:
            note = 'its profile reaches a bound of the range'
        else:
            note = f'its 95 % interval spans {interval.width_u:.2f} of the scaled range'
        estimates.append(ThresholdEstimate(fp.path, fp.from_unit(float(fit.u[interval.index])),
                                           ends[0], ends[1], fp.low, fp.high,
                                           interval.determined, note))
    r = misfit(fit.u)
    return ThresholdFitResult(tuple(estimates), fit.chi2, r, misfit.thresholds_v(fit.u),
                              fit.evaluations, fit)
