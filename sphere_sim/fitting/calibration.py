"""Calibration of the declared-uncertain parameters to the paper's pull-in (Fig. 4).

Only parameters that a parameter set declares uncertain, each with a range, a reason and a
target, may move, and only one observation is a target:

``fig4_threshold``
    Fig. 4: the kick rises sharply between 40 and 45 V and the beams pull in "for voltages
    larger than 44 V". The model's dynamic pull-in threshold of 5 ms pulses on all beams, with
    the sphere on, is put at ``TARGET_THRESHOLD_V``. The rest condition of §4.1 (tips on the
    ground plate's front edge) is checked for every hypothesis.

The paper's other facts (the kick's direction and size, the width against tilt, the holding
of a tilted sphere) are never targets: they test the calibrated model (test_paper_facts.py).

The parameters of the target are fitted jointly: one observation cannot pin several
parameters, so the fit takes the smallest change from a reference (Table A1's value; the
range's centre where the range excludes the table's value, which then says nothing about where
inside the range the value lies) that meets the target, in coordinates where each range spans
0..1 (geometric for ranges of more than ``GEOMETRIC_RANGE_RATIO``). It moves along the
threshold's gradient at the reference, each coordinate held ``RANGE_MARGIN`` off its bounds,
and bisects along that path. A range is a physical bound: a target the path cannot bracket is
not forced; the fit stops at the path's nearer end and :attr:`Fit.reached` is False, so that
the shortfall is reported.
"""

import dataclasses
import math
from collections.abc import Callable, Sequence

import numpy as np
from numpy.typing import NDArray

from sphere_sim.model.assembly import assemble
from sphere_sim.model.initial_state import rest_state
from sphere_sim.model.parameters import CALIBRATION_TARGETS, ParameterSet, UncertainParameter
from sphere_sim.model.scene import load_scene
from sphere_sim.studies.pullin import dynamic_threshold

# §4.1: "for voltages larger than 44 V a pull-in occurs"; Fig. 4's kick rises sharply in 40-45 V:
# the fit aims at the middle of (44, 45).
# The set the calibration fits and rewrites, and the literal reading of Table A1 it starts from.
CALIBRATED_SET = 'calibrated'
LITERAL_SET = 'table_a1'
TARGET_THRESHOLD_V = 44.5
FIT_TOLERANCE_V = 0.25
MAX_FIT_STEPS = 12
# A range spanning more than this ratio is fitted in log coordinates.
GEOMETRIC_RANGE_RATIO = 10.0
# A fitted value keeps this share of its range from either bound ("off its bounds").
RANGE_MARGIN = 0.05
# Step of the threshold's gradient at the reference, in range coordinates.
GRADIENT_STEP = 0.05


@dataclasses.dataclass(frozen=True)
class Fit:
    """The outcome of fitting one declared-uncertain parameter (jointly with the others of its
    target: ``observed`` and ``history`` are the joint fit's)."""

    spec: UncertainParameter
    value: float
    observed: float  # threshold (V) at the fitted values
    target: float
    # (value of this parameter, observed) of every evaluation, in order
    history: tuple[tuple[float, float], ...]

    unit = 'V'

    @property
    def reached(self) -> bool:
        """False when the declared ranges stopped the fit short of its target."""
        return abs(self.observed - self.target) < FIT_TOLERANCE_V

    @property
    def at_margin(self) -> bool:
        """True when the value sits at its range's margin (the fit leaned on that bound)."""
        return abs(range_coordinate(self.spec, self.value) - 0.5) >= 0.5 - RANGE_MARGIN - 1e-9


def evaluate(params: ParameterSet, with_beams_only: bool = True) -> tuple[float, float, bool]:
    """Dynamic thresholds with and without the sphere, and the rest contact, for ``params``."""
    scene = load_scene('four_beam_pulse')
    model = assemble(scene, params)
    x_rest = rest_state(model)
    front = model.ground_gaps(x_rest)[1]
    with_sphere, _ = dynamic_threshold(model, x_rest)
    beams_only = float('nan')
    if with_beams_only:
        bare = assemble(scene.replace(sphere=False), params)
        beams_only, _ = dynamic_threshold(bare, rest_state(bare))
    return with_sphere, beams_only, bool(np.all(front < 0))


def threshold_v(params: ParameterSet) -> float:
    """Fig. 4's observable: the dynamic pull-in threshold with the sphere on (V)."""
    return evaluate(params, with_beams_only=False)[0]


def with_value(params: ParameterSet, spec: UncertainParameter, value: float) -> ParameterSet:
    """``params`` with ``spec``'s path and every path tied to it set to ``value``."""
    return params.replace(**{path: float(value) for path in spec.paths})


def with_values(params: ParameterSet, specs: Sequence[UncertainParameter],
                values: Sequence[float]) -> ParameterSet:
    for spec, value in zip(specs, values, strict=True):
        params = with_value(params, spec, value)
    return params


def _geometric(spec: UncertainParameter) -> bool:
    return spec.low > 0 and spec.high / spec.low > GEOMETRIC_RANGE_RATIO


def range_coordinate(spec: UncertainParameter, value: float) -> float:
    """``value`` in ``spec``'s range coordinates: 0 at its low end, 1 at its high end."""
    if _geometric(spec):
        return math.log(value / spec.low) / math.log(spec.high / spec.low)
    return (value - spec.low) / (spec.high - spec.low)


def value_at(spec: UncertainParameter, coordinate: float) -> float:
    """The inverse of :func:`range_coordinate`."""
    if _geometric(spec):
        return spec.low * (spec.high / spec.low) ** coordinate
    return spec.low + coordinate * (spec.high - spec.low)


def bisect(observe: Callable[[float], float], low: float, high: float, target: float,
           tolerance: float, geometric: bool = False,
           progress: Callable[[float, float], object] | None = None
           ) -> tuple[float, float, tuple[tuple[float, float], ...]]:
    """Bisection of a monotone ``observe(value)`` for ``target`` within [low, high].

    Returns ``(value, observed, history)``. When [low, high] does not bracket the target, the
    end whose observation lies closer to it is returned: the range is a physical bound and is
    never stretched; the caller reports how far the target was missed (:attr:`Fit.reached`).
    """
    history: list[tuple[float, float]] = []

    def look(value: float) -> float:
        observed = observe(value)
        history.append((value, observed))
        if progress is not None:
            progress(value, observed)
        return observed

    f_low, f_high = look(low), look(high)
    mid, f_mid = (low, f_low) if abs(f_low - target) < abs(f_high - target) else (high, f_high)
    if (f_low - target) * (f_high - target) > 0:
        return mid, f_mid, tuple(history)
    for _ in range(MAX_FIT_STEPS):
        if abs(f_mid - target) < tolerance:
            break
        mid = math.sqrt(low * high) if geometric else 0.5 * (low + high)
        f_mid = look(mid)
        if (f_low - target) * (f_mid - target) <= 0:
            high, f_high = mid, f_mid
        else:
            low, f_low = mid, f_mid
    return mid, f_mid, tuple(history)


def start_coordinate(spec: UncertainParameter, reference_value: float) -> float:
    """Where the joint fit starts for ``spec``: the reference value inside the range's margins;
    a reference outside the range (a table value the range excludes) says nothing about where
    inside it the value lies, so the range's centre."""
    coordinate = range_coordinate(spec, reference_value)
    if not 0.0 <= coordinate <= 1.0:
        return 0.5
    return min(max(coordinate, RANGE_MARGIN), 1.0 - RANGE_MARGIN)


def fit_jointly(params: ParameterSet, specs: Sequence[UncertainParameter],
                reference: ParameterSet,
                progress: Callable[[float, float], object] | None = None) -> list[Fit]:
    """Fit ``specs`` jointly to Fig. 4's threshold: the smallest move from ``reference``.

    Parameters
    ----------
    params : ParameterSet
        Values of everything not fitted.
    specs : sequence of UncertainParameter
        All of target ``fig4_threshold``.
    reference : ParameterSet
        Where the move starts (Table A1), each value brought inside its range's margins.

    Returns
    -------
    list of Fit
        One per spec, in order.
    """
    target, tolerance = TARGET_THRESHOLD_V, FIT_TOLERANCE_V
    start = np.array([start_coordinate(spec, reference.get(spec.path)) for spec in specs])
    history: list[tuple[tuple[float, ...], float]] = []

    def candidate(coordinates: NDArray[np.float64]) -> ParameterSet:
        inside = np.clip(coordinates, RANGE_MARGIN, 1.0 - RANGE_MARGIN)
        return with_values(params, specs, [value_at(spec, c)
                                           for spec, c in zip(specs, inside, strict=True)])

    def look(coordinates: NDArray[np.float64]) -> float:
        trial = candidate(coordinates)
        observed = threshold_v(trial)
        history.append((tuple(trial.get(spec.path) for spec in specs), observed))
        if progress is not None:
            progress(history[-1][0][0], observed)
        return observed

    f_start = look(start)
    gradient = np.empty(len(specs))
    for i in range(len(specs)):
        step = np.zeros(len(specs))
        forward = start[i] + GRADIENT_STEP <= 1.0 - RANGE_MARGIN
        step[i] = GRADIENT_STEP if forward else -GRADIENT_STEP
        gradient[i] = (look(start + step) - f_start) / step[i]
    # Along the gradient, towards the target, until every coordinate has met its margin.
    direction = gradient * math.copysign(1.0, target - f_start)
    room = [((1.0 - RANGE_MARGIN - c) if d > 0 else (c - RANGE_MARGIN)) / abs(d)
            for c, d in zip(start, direction, strict=True) if d != 0.0]
    reach = max(room) if room else 0.0
    if abs(f_start - target) < tolerance or reach == 0.0:
        end, observed = start, f_start
    else:
        distance, observed, _ = bisect(lambda s: look(start + s * direction), 0.0, reach, target,
                                       tolerance)
        end = start + distance * direction
    fitted = candidate(end)
    return [Fit(spec, fitted.get(spec.path), observed, target,
                tuple((values[i], seen) for values, seen in history))
            for i, spec in enumerate(specs)]


def calibrate(params: ParameterSet, uncertain: Sequence[UncertainParameter],
              progress: Callable[[float, float], object] | None = None,
              reference: ParameterSet | None = None) -> tuple[ParameterSet, list[Fit]]:
    """Fit every declared-uncertain parameter of Fig. 4's threshold jointly.

    Parameters
    ----------
    params : ParameterSet
        Values of the parameters not being fitted.
    uncertain : sequence of UncertainParameter
        Those held at an estimate (``ESTIMATE_TARGET``) are left as they are.
    reference : ParameterSet, optional
        Where the fit starts from (default: Table A1 read literally).

    Returns
    -------
    params : ParameterSet
        With the fitted values.
    fits : list of Fit
        One per fitted parameter.
    """
    from sphere_sim.model.parameters import load_parameter_set

    reference = load_parameter_set(LITERAL_SET) if reference is None else reference
    specs = [spec for spec in uncertain if spec.target in CALIBRATION_TARGETS]
    if not specs:
        return params, []
    fits = fit_jointly(params, specs, reference, progress)
    return with_values(params, specs, [f.value for f in fits]), fits
