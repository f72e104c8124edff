"""Optimised kicks (§4.1): maximise the rotation in a kick's nominal direction.

The paper used a genetic algorithm on the two pulse widths and the delay between the rising
edges; here scipy's differential evolution does the same search, seeded and with parallel
workers. The objective is the final normal's displacement projected on the nominal direction,
from rest at zero tilt, over the kick window.
"""

import dataclasses
import math
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from scipy.optimize import differential_evolution

from sphere_sim.kicks.design import KICK_RELAXATION, KickDesign, final_normal, simulate_kick
from sphere_sim.kicks.discrete import KickResult
from sphere_sim.kicks.engine import SerialEngine, engine_for
from sphere_sim.kicks.process_models import process_model
from sphere_sim.model.initial_state import rest_state
from sphere_sim.model.parameters import ParameterSet
from sphere_sim.model.rotations import angle_between

WIDTH_BOUNDS_S = (0.2e-3, 8e-3)
DELAY_BOUNDS_S = (-6e-3, 6e-3)
OPTIMISATION_RTOL = 1e-5  # the outcome changes by < 1e-4 deg between 1e-5 and 1e-7 here
NORMAL_AT_REST = np.array([0.0, 0.0, 1.0])


@dataclasses.dataclass(frozen=True)
class OptimisedKick:
    design: KickDesign
    rotation_deg: float
    direction_deg: float
    along_deg: float  # component of the displacement along the nominal direction
    settle_time_s: float
    peak_deviation_deg: float
    evaluations: int
    seed: int

    def to_dict(self) -> dict[str, Any]:
        out = dataclasses.asdict(self)
        out['design']['direction_deg'] = math.degrees(self.design.direction_rad)
        return out


class _Objective:
    """Picklable objective for parallel workers: -(displacement along the nominal direction).

    It carries its inputs and the rest state every kick starts from, relaxed once by the
    process that starts the search: no worker relaxes it again. Each process assembles the
    model once (:func:`~sphere_sim.kicks.process_models.process_model`), however many times
    the objective is unpickled there.
    """

    def __init__(self, scene_name: str, params: ParameterSet | None,
                 template: KickDesign) -> None:
        self.scene_name = scene_name
        self.params = params
        self.template = template
        self.x_rest = rest_state(process_model(params, scene_name), relaxation=KICK_RELAXATION)

    def design(self, v: Sequence[float]) -> KickDesign:
        return dataclasses.replace(self.template, width_low_s=float(v[0]),
                                   width_high_s=float(v[1]), delay_s=float(v[2]))

    def outcome(self, v: Sequence[float]) -> KickResult:
        result, _ = simulate_kick(process_model(self.params, self.scene_name), NORMAL_AT_REST,
                                  self.design(v).programme(), rtol=OPTIMISATION_RTOL,
                                  x_rest=self.x_rest)
        return result

    def __call__(self, v: Sequence[float]) -> float:
        # The final normal alone: the transient's peak and settling time are not searched on.
        normal = final_normal(process_model(self.params, self.scene_name), NORMAL_AT_REST,
                              self.design(v).programme(), rtol=OPTIMISATION_RTOL,
                              x_rest=self.x_rest)
        d = self.template.direction_rad
        return -float(normal[0] * math.cos(d) + normal[1] * math.sin(d))


def optimise_kick(template: KickDesign | None = None, params: ParameterSet | None = None,
                  seed: int = 1, popsize: int = 8, maxiter: int = 12,
                  workers: int | SerialEngine = 1,
                  progress: Callable[[float], object] | None = None) -> OptimisedKick:
    """Differential evolution over (width_low_s, width_high_s, delay_s).

    Parameters
    ----------
    params : ParameterSet, optional
        The default set unless given (the calibration passes candidates).
    workers : int or engine
        Local processes, or a started engine of :mod:`sphere_sim.kicks.engine` (left open).
        The population is evaluated a generation at a time whatever the count, so that the
        same seed finds the same kick on one worker as on many.

    Returns
    -------
    OptimisedKick
    """
    template = KickDesign() if template is None else template
    objective = _Objective('rest', params, template)
    bounds = [WIDTH_BOUNDS_S, WIDTH_BOUNDS_S, DELAY_BOUNDS_S]

    def callback(intermediate_result: Any) -> None:
        if progress is not None:
            progress(-intermediate_result.fun)

    with engine_for(workers) as engine:
        result = differential_evolution(objective, bounds, seed=seed, popsize=popsize,
                                        maxiter=maxiter, tol=1e-3, polish=False,
                                        workers=engine, updating='deferred',
                                        callback=callback)
        # On a worker, which has the model already.
        best = engine(objective.outcome, [result.x])[0]
    normal0 = NORMAL_AT_REST
    d = best.normal[:2]
    return OptimisedKick(
        design=objective.design(result.x),
        rotation_deg=math.degrees(angle_between(normal0, best.normal)),
        direction_deg=math.degrees(math.atan2(d[1], d[0])),
        along_deg=math.degrees(-result.fun),
        settle_time_s=best.settle_time_s,
        peak_deviation_deg=math.degrees(best.peak_deviation_rad),
        evaluations=int(result.nfev),
        seed=seed,
    )
